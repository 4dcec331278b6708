//! Zenoh key expressions of a run (DESIGN.md §3), defined once for every process.
//!
//! All keys live under `lhm/<run>/`. A run id and an actor id become one key chunk each, so they
//! must be non-empty and free of `/`, `*`, `$`, `?` and `#` ([`check_chunk`]).

use crate::Role;

/// Why a name cannot be used as a key chunk.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} {value:?} cannot be part of a key expression: {reason}")]
pub struct KeyError {
    pub what: &'static str,
    pub value: String,
    pub reason: &'static str,
}

/// A run id or process id must be one non-empty key chunk without wildcards.
pub fn check_chunk(what: &'static str, value: &str) -> Result<(), KeyError> {
    let fail = |reason| {
        Err(KeyError {
            what,
            value: value.to_owned(),
            reason,
        })
    };
    if value.is_empty() {
        return fail("it is empty");
    }
    if value.contains(['/', '*', '$', '?', '#']) {
        return fail("it contains one of / * $ ? #");
    }
    if value.chars().any(char::is_whitespace) {
        return fail("it contains whitespace");
    }
    Ok(())
}

/// The key chunk of a role: `teacher1`, `teacher2`, `student`, `vla`.
pub fn role_chunk(role: Role) -> &'static str {
    match role {
        Role::Teacher1 => "teacher1",
        Role::Teacher2 => "teacher2",
        Role::Student => "student",
        Role::Vla => "vla",
        Role::Unspecified => "unspecified",
    }
}

/// Parses a role name as written on command lines and in keys.
pub fn parse_role(name: &str) -> Option<Role> {
    match name {
        "teacher1" => Some(Role::Teacher1),
        "teacher2" => Some(Role::Teacher2),
        "student" => Some(Role::Student),
        "vla" => Some(Role::Vla),
        _ => None,
    }
}

/// Trajectory chunks of one actor: `lhm/<run>/traj/<role>/<actor>`.
pub fn trajectory(run: &str, role: Role, actor: &str) -> String {
    format!("lhm/{run}/traj/{}/{actor}", role_chunk(role))
}

/// Every actor's trajectories for a role (a subscriber's key).
pub fn trajectory_all(run: &str, role: Role) -> String {
    format!("lhm/{run}/traj/{}/*", role_chunk(role))
}

/// Weights of a role: published there and answered by the `latest` queryable.
pub fn policy(run: &str, role: Role) -> String {
    format!("lhm/{run}/policy/{}", role_chunk(role))
}

/// The DAgger label queryable.
pub fn dagger_label(run: &str) -> String {
    format!("lhm/{run}/dagger/label")
}

/// A process's liveliness token.
pub fn status(run: &str, process: &str) -> String {
    format!("lhm/{run}/status/{process}")
}

/// Every liveliness token of a run.
pub fn status_all(run: &str) -> String {
    format!("lhm/{run}/status/*")
}

/// The process name in a `status/<process>` key, if the key is one.
pub fn process_of_status_key<'a>(run: &str, key: &'a str) -> Option<&'a str> {
    let rest = key.strip_prefix("lhm/")?.strip_prefix(run)?;
    rest.strip_prefix("/status/")
        .filter(|p| !p.is_empty() && !p.contains('/'))
}

/// Telemetry of one process (may drop under congestion).
pub fn metrics(run: &str, process: &str) -> String {
    format!("lhm/{run}/metrics/{process}")
}

/// Every process's telemetry.
pub fn metrics_all(run: &str) -> String {
    format!("lhm/{run}/metrics/*")
}

/// Sampled episodes (poses) of one actor, for recording.
pub fn episode(run: &str, role: Role, actor: &str) -> String {
    format!("lhm/{run}/episode/{}/{actor}", role_chunk(role))
}

/// Every actor's sampled episodes for a role.
pub fn episode_all(run: &str, role: Role) -> String {
    format!("lhm/{run}/episode/{}/*", role_chunk(role))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_have_the_documented_shape() {
        assert_eq!(
            trajectory("r1", Role::Teacher1, "a-0"),
            "lhm/r1/traj/teacher1/a-0"
        );
        assert_eq!(policy("r1", Role::Student), "lhm/r1/policy/student");
        assert_eq!(dagger_label("r1"), "lhm/r1/dagger/label");
        assert_eq!(status("r1", "learner"), "lhm/r1/status/learner");
        assert_eq!(
            process_of_status_key("r1", "lhm/r1/status/actor-3"),
            Some("actor-3")
        );
        assert_eq!(process_of_status_key("r1", "lhm/r2/status/actor-3"), None);
        assert_eq!(process_of_status_key("r1", "lhm/r1/status/"), None);
        for role in [Role::Teacher1, Role::Teacher2, Role::Student, Role::Vla] {
            assert_eq!(parse_role(role_chunk(role)), Some(role));
        }
    }

    #[test]
    fn bad_chunks_are_refused() {
        assert!(check_chunk("run id", "run-1").is_ok());
        for bad in ["", "a/b", "a*", "x$y", "a b", "q?", "h#"] {
            let err = check_chunk("run id", bad).unwrap_err();
            assert!(err.to_string().contains("run id"), "{err}");
        }
    }
}
