//! Episode terminations and the paper's metrics, as pure functions.

use rapier3d::math::Vector;

/// A cycle succeeds when the object's root ends within this distance of its goal (paper Sec. 4.1).
pub const SUCCESS_RADIUS: f32 = 0.2;

/// Fall: any body not in `exempt` (feet; hands, which touch the floor when picking up) below
/// `min_height` metres.
pub fn fallen(body_heights: &[f32], exempt: &[bool], min_height: f32) -> bool {
    body_heights
        .iter()
        .zip(exempt.iter().chain(std::iter::repeat(&false)))
        .any(|(h, skip)| !skip && *h < min_height)
}

/// The bodies [`fallen`] ignores: feet, and hands (which touch the floor when picking up).
pub fn fall_exempt(model: &crate::mjcf::CharacterModel) -> Vec<bool> {
    model
        .bodies
        .iter()
        .map(|b| b.name.ends_with("foot") || b.name.ends_with("hand"))
        .collect()
}

/// Dist: the final placement error in metres.
pub fn placement_error(object_pos: Vector, goal: Vector) -> f32 {
    (object_pos - goal).length()
}

/// Per-cycle success.
pub fn cycle_success(object_pos: Vector, goal: Vector) -> bool {
    placement_error(object_pos, goal) <= SUCCESS_RADIUS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fall_ignores_exempt_bodies() {
        let exempt = [false, false, true, true];
        assert!(!fallen(&[0.9, 1.2, 0.02, 0.05], &exempt, 0.15));
        assert!(fallen(&[0.1, 1.2, 0.02, 0.05], &exempt, 0.15));
        assert!(fallen(&[0.9, 0.14, 0.5, 0.5], &exempt, 0.15));
        // Bodies past the exempt list are checked.
        assert!(fallen(&[0.9, 0.9, 0.9, 0.9, 0.01], &exempt, 0.15));
    }

    #[test]
    fn success_is_within_twenty_centimetres_in_3d() {
        let goal = Vector::new(1.0, 1.0, 0.75);
        assert!(cycle_success(Vector::new(1.1, 1.1, 0.75), goal));
        assert!(
            !cycle_success(Vector::new(1.0, 1.0, 0.5), goal),
            "dropped beside the table"
        );
        assert!((placement_error(Vector::new(1.3, 1.4, 0.75), goal) - 0.5).abs() < 1e-6);
    }
}
