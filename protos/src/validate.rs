//! Per-message content checks behind [`crate::WireMessage::validate`].
//!
//! Everything here runs on untrusted values: lengths are compared with checked arithmetic and
//! nothing is indexed before its length has been checked.

use std::fmt::Arguments;

use crate::{
    ActorState, ActorStatus, EpisodeFrames, EpisodeStats, LabelReply, LabelRequest, Metrics,
    Normalizer, PolicyWeights, Role, Stage, TrajectoryChunk, WireError, WireMessage,
};

type Result = std::result::Result<(), WireError>;

/// Builds [`WireError::Invalid`] errors for one message type.
struct Check {
    message: &'static str,
}

impl Check {
    fn of<M: WireMessage>() -> Self {
        Self {
            message: M::FULL_NAME,
        }
    }

    /// `reason` is `format_args!`, so nothing is formatted or allocated unless the check fails.
    fn ensure(&self, ok: bool, field: &'static str, reason: Arguments<'_>) -> Result {
        if ok {
            return Ok(());
        }
        Err(WireError::Invalid {
            message: self.message,
            field,
            reason: reason.to_string(),
        })
    }

    fn non_empty(&self, field: &'static str, value: &str) -> Result {
        self.ensure(!value.is_empty(), field, format_args!("must not be empty"))
    }

    fn positive(&self, field: &'static str, value: u32) -> Result {
        self.ensure(value > 0, field, format_args!("must be > 0"))
    }

    /// A per-step (or per-state) array: `len == n`.
    fn len(&self, field: &'static str, len: usize, n: u32) -> Result {
        let ok = usize::try_from(n) == Ok(len);
        self.ensure(ok, field, format_args!("has {len} elements, expected {n}"))
    }

    /// A flattened `rows x cols` matrix: `len == rows * cols`, computed without overflow.
    fn shape(&self, field: &'static str, len: usize, rows: u32, cols: u32) -> Result {
        let expected = usize::try_from(rows)
            .ok()
            .zip(usize::try_from(cols).ok())
            .and_then(|(rows, cols)| rows.checked_mul(cols));
        match expected {
            Some(expected) => self.ensure(
                expected == len,
                field,
                format_args!("has {len} elements, expected {rows} * {cols} = {expected}"),
            ),
            None => self.ensure(
                false,
                field,
                format_args!("{rows} * {cols} overflows usize"),
            ),
        }
    }

    fn finite(&self, field: &'static str, values: &[f32]) -> Result {
        match values.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => self.ensure(
                false,
                field,
                format_args!("[{i}] = {} is not finite", values[i]),
            ),
        }
    }

    fn finite_non_negative(&self, field: &'static str, values: &[f32]) -> Result {
        self.finite(field, values)?;
        match values.iter().position(|v| *v < 0.0) {
            None => Ok(()),
            Some(i) => self.ensure(
                false,
                field,
                format_args!("[{i}] = {} is negative", values[i]),
            ),
        }
    }

    /// A known role other than `ROLE_UNSPECIFIED`.
    fn role(&self, field: &'static str, value: i32) -> Result {
        let ok = matches!(Role::try_from(value), Ok(role) if role != Role::Unspecified);
        self.ensure(ok, field, format_args!("{value} is not a specified Role"))
    }
}

pub(crate) fn trajectory_chunk(m: &TrajectoryChunk) -> Result {
    let c = Check::of::<TrajectoryChunk>();
    c.non_empty("run_id", &m.run_id)?;
    c.non_empty("actor_id", &m.actor_id)?;
    c.role("role", m.role)?;
    c.positive("num_steps", m.num_steps)?;
    c.positive("obs_dim", m.obs_dim)?;
    c.positive("act_dim", m.act_dim)?;
    // amp_dim may be 0 (policy trained without AMP); amp_features must then be empty.
    let n = m.num_steps;
    c.shape("observations", m.observations.len(), n, m.obs_dim)?;
    c.shape("actions", m.actions.len(), n, m.act_dim)?;
    c.shape("amp_features", m.amp_features.len(), n, m.amp_dim)?;
    c.len("log_probs", m.log_probs.len(), n)?;
    c.len("values", m.values.len(), n)?;
    c.len("rewards", m.rewards.len(), n)?;
    c.len("dones", m.dones.len(), n)?;
    c.len("truncated", m.truncated.len(), n)?;
    c.len("truncation_values", m.truncation_values.len(), n)?;
    // Empty when no step of the chunk is stopped, else one flag a step.
    if !m.gait_stopped.is_empty() {
        c.len("gait_stopped", m.gait_stopped.len(), n)?;
    }
    if !m.gait_ramping.is_empty() {
        c.len("gait_ramping", m.gait_ramping.len(), n)?;
    }

    c.finite("observations", &m.observations)?;
    c.finite("actions", &m.actions)?;
    c.finite("log_probs", &m.log_probs)?;
    c.finite("values", &m.values)?;
    c.finite("rewards", &m.rewards)?;
    c.finite("truncation_values", &m.truncation_values)?;
    c.finite("amp_features", &m.amp_features)?;
    c.finite("bootstrap_value", &[m.bootstrap_value])?;

    // The three arrays have num_steps elements each (checked above), so zip covers every step.
    let steps = m.dones.iter().zip(&m.truncated).zip(&m.truncation_values);
    for (t, ((&done, &truncated), &value)) in steps.enumerate() {
        // Both set would be ambiguous for the return computation: bootstrap or not?
        c.ensure(
            !(done && truncated),
            "truncated",
            format_args!("step {t} is both done and truncated"),
        )?;
        // A value on a step that was not truncated means the arrays are misaligned.
        c.ensure(
            truncated || value == 0.0,
            "truncation_values",
            format_args!("[{t}] = {value} but step {t} is not truncated"),
        )?;
    }

    m.episodes
        .iter()
        .enumerate()
        .try_for_each(|(i, episode)| episode_stats(&c, i, episode))
}

fn episode_stats(c: &Check, i: usize, e: &EpisodeStats) -> Result {
    let ret = e.episode_return;
    c.ensure(
        ret.is_finite(),
        "episodes.episode_return",
        format_args!("episode {i}: {ret} is not finite"),
    )?;
    c.ensure(
        e.length > 0,
        "episodes.length",
        format_args!("episode {i}: must be > 0"),
    )?;
    let (attempted, succeeded) = (e.cycles_attempted, e.cycles_succeeded);
    c.ensure(
        succeeded <= attempted,
        "episodes.cycles_succeeded",
        format_args!("episode {i}: {succeeded} > cycles_attempted {attempted}"),
    )?;
    // One placement error per attempted cycle.
    let errors = &e.final_placement_error_m;
    c.len("episodes.final_placement_error_m", errors.len(), attempted)?;
    c.finite_non_negative("episodes.final_placement_error_m", errors)?;
    for (name, v) in &e.reward_terms {
        c.ensure(
            v.is_finite(),
            "episodes.reward_terms",
            format_args!("episode {i}: term {name:?} = {v} is not finite"),
        )?;
    }
    Ok(())
}

/// Checks a normaliser if present (absent means identity).
fn normalizer(c: &Check, field: &'static str, n: Option<&Normalizer>) -> Result {
    let Some(n) = n else { return Ok(()) };
    let count = n.count;
    c.ensure(
        count.is_finite() && count >= 0.0,
        field,
        format_args!("count = {count} must be finite and >= 0"),
    )?;
    let (mean, var) = (n.mean.len(), n.var.len());
    c.ensure(
        mean == var,
        field,
        format_args!("mean has {mean} elements but var has {var}"),
    )?;
    for (name, v) in [("epsilon", n.epsilon), ("clip", n.clip)] {
        c.ensure(
            v.is_finite() && v >= 0.0,
            field,
            format_args!("{name} = {v} must be finite and >= 0 (0: unset)"),
        )?;
    }
    c.finite(field, &n.mean)?;
    c.finite_non_negative(field, &n.var)
}

pub(crate) fn policy_weights(m: &PolicyWeights) -> Result {
    let c = Check::of::<PolicyWeights>();
    c.non_empty("run_id", &m.run_id)?;
    c.role("role", m.role)?;
    c.ensure(
        !m.safetensors.is_empty(),
        "safetensors",
        format_args!("must not be empty"),
    )?;
    c.non_empty("config_json", &m.config_json)?;
    normalizer(&c, "obs_normalizer", m.obs_normalizer.as_ref())?;
    normalizer(&c, "amp_normalizer", m.amp_normalizer.as_ref())
}

pub(crate) fn label_request(m: &LabelRequest) -> Result {
    let c = Check::of::<LabelRequest>();
    c.non_empty("run_id", &m.run_id)?;
    c.positive("num_states", m.num_states)?;
    c.positive("obs_dim", m.obs_dim)?;
    c.shape(
        "observations",
        m.observations.len(),
        m.num_states,
        m.obs_dim,
    )?;
    c.len("stages", m.stages.len(), m.num_states)?;
    c.finite("observations", &m.observations)?;
    // The stage picks the supervising teacher, so a missing or unknown one cannot be labelled.
    m.stages.iter().enumerate().try_for_each(|(i, &stage)| {
        let ok = matches!(Stage::try_from(stage), Ok(s) if s != Stage::Unspecified);
        c.ensure(
            ok,
            "stages",
            format_args!("[{i}] = {stage} is not a specified Stage"),
        )
    })
}

pub(crate) fn label_reply(m: &LabelReply) -> Result {
    let c = Check::of::<LabelReply>();
    if !m.error.is_empty() {
        // A failed reply must not carry labels that someone could train on by mistake.
        let empty = [
            ("actions", m.actions.is_empty()),
            ("teachers", m.teachers.is_empty()),
            ("teacher_versions", m.teacher_versions.is_empty()),
        ];
        return empty.into_iter().try_for_each(|(field, ok)| {
            c.ensure(ok, field, format_args!("must be empty when error is set"))
        });
    }
    c.positive("num_states", m.num_states)?;
    c.positive("act_dim", m.act_dim)?;
    c.shape("actions", m.actions.len(), m.num_states, m.act_dim)?;
    c.len("teachers", m.teachers.len(), m.num_states)?;
    c.len("teacher_versions", m.teacher_versions.len(), m.num_states)?;
    c.finite("actions", &m.actions)?;
    m.teachers
        .iter()
        .try_for_each(|&teacher| c.role("teachers", teacher))
}

pub(crate) fn actor_status(m: &ActorStatus) -> Result {
    let c = Check::of::<ActorStatus>();
    c.non_empty("run_id", &m.run_id)?;
    c.non_empty("actor_id", &m.actor_id)?;
    c.role("role", m.role)?;
    let state = m.state;
    let ok = matches!(ActorState::try_from(state), Ok(s) if s != ActorState::Unspecified);
    c.ensure(
        ok,
        "state",
        format_args!("{state} is not a specified ActorState"),
    )
}

pub(crate) fn metrics(m: &Metrics) -> Result {
    let c = Check::of::<Metrics>();
    c.non_empty("run_id", &m.run_id)?;
    c.non_empty("process", &m.process)?;
    // Values may be NaN or infinite on purpose: a diverged loss must reach the dashboards.
    c.ensure(
        !m.values.contains_key(""),
        "values",
        format_args!("metric names must not be empty"),
    )
}

pub(crate) fn episode_frames(m: &EpisodeFrames) -> Result {
    let c = Check::of::<EpisodeFrames>();
    c.non_empty("run_id", &m.run_id)?;
    c.non_empty("actor_id", &m.actor_id)?;
    c.role("role", m.role)?;
    c.non_empty("task_id", &m.task_id)?;
    c.ensure(
        m.frame_dt.is_finite() && m.frame_dt > 0.0,
        "frame_dt",
        format_args!("{} is not a positive number of seconds", m.frame_dt),
    )?;
    c.positive("num_frames", m.num_frames)?;
    c.positive("num_bodies", m.num_bodies)?;
    let n = m.num_frames;
    let per_frame = |k: u32, each: u32| k.saturating_mul(each);
    c.shape(
        "body_positions",
        m.body_positions.len(),
        n,
        per_frame(m.num_bodies, 3),
    )?;
    c.shape(
        "body_rotations",
        m.body_rotations.len(),
        n,
        per_frame(m.num_bodies, 4),
    )?;
    c.shape(
        "object_positions",
        m.object_positions.len(),
        n,
        per_frame(m.num_objects, 3),
    )?;
    c.shape(
        "object_rotations",
        m.object_rotations.len(),
        n,
        per_frame(m.num_objects, 4),
    )?;
    c.finite("body_positions", &m.body_positions)?;
    c.finite("body_rotations", &m.body_rotations)?;
    c.finite("object_positions", &m.object_positions)?;
    c.finite("object_rotations", &m.object_rotations)
}
