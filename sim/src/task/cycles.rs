//! Reset-free cycles: an episode carries the ordered (object, goal) pairs; the handoff to the next
//! pair is decided by the three switching parameters — the object has settled (speed), it is
//! close enough to its goal (distance), and it stayed so long enough or the cycle ran out of time
//! (timing) — never by a reset.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SwitchParams {
    /// Object speed below which it counts as settled, m/s.
    pub settle_speed: f32,
    /// Object-to-goal distance within which the cycle counts as placed, m.
    pub success_distance: f32,
    /// Control steps the object must stay settled and placed before the handoff.
    pub hold_steps: u32,
    /// Control steps after which the cycle is handed off whatever its state.
    pub max_cycle_steps: u32,
}

impl Default for SwitchParams {
    fn default() -> Self {
        Self {
            settle_speed: 0.05,
            success_distance: 0.2,
            hold_steps: 15,
            max_cycle_steps: 600,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleResult {
    pub success: bool,
    /// Placement error at the handoff, m.
    pub dist: f32,
    pub steps: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handoff {
    /// Stay on the current pair.
    Continue,
    /// The current pair ended; the next one starts now.
    Next,
    /// The last pair ended: the episode is complete.
    Done,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CycleTracker {
    pub params: SwitchParams,
    pub pairs: usize,
    pub current: usize,
    steps: u32,
    held: u32,
    pub results: Vec<CycleResult>,
}

impl CycleTracker {
    pub fn new(pairs: usize, params: SwitchParams) -> Self {
        Self {
            params,
            pairs,
            current: 0,
            steps: 0,
            held: 0,
            results: Vec::new(),
        }
    }

    pub fn done(&self) -> bool {
        self.current >= self.pairs
    }

    /// Called once per control step with the current object's distance to its goal and speed.
    pub fn update(&mut self, object_to_goal: f32, object_speed: f32) -> Handoff {
        if self.done() {
            return Handoff::Done;
        }
        self.steps += 1;
        let placed = object_to_goal <= self.params.success_distance;
        if placed && object_speed <= self.params.settle_speed {
            self.held += 1;
        } else {
            self.held = 0;
        }
        if self.held >= self.params.hold_steps || self.steps >= self.params.max_cycle_steps {
            self.results.push(CycleResult {
                success: placed,
                dist: object_to_goal,
                steps: self.steps,
            });
            self.current += 1;
            self.steps = 0;
            self.held = 0;
            return if self.done() {
                Handoff::Done
            } else {
                Handoff::Next
            };
        }
        Handoff::Continue
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> SwitchParams {
        SwitchParams {
            settle_speed: 0.05,
            success_distance: 0.2,
            hold_steps: 3,
            max_cycle_steps: 10,
        }
    }

    #[test]
    fn hands_off_after_the_object_settles_at_its_goal() {
        let mut c = CycleTracker::new(2, params());
        assert_eq!(c.update(1.0, 0.0), Handoff::Continue);
        assert_eq!(
            c.update(0.1, 0.5),
            Handoff::Continue,
            "placed but still moving"
        );
        assert_eq!(c.update(0.1, 0.01), Handoff::Continue);
        assert_eq!(c.update(0.1, 0.01), Handoff::Continue);
        assert_eq!(
            c.update(0.3, 0.01),
            Handoff::Continue,
            "nudged out: the hold restarts"
        );
        assert_eq!(c.update(0.15, 0.0), Handoff::Continue);
        assert_eq!(c.update(0.15, 0.0), Handoff::Continue);
        assert_eq!(c.update(0.15, 0.0), Handoff::Next);
        assert_eq!(c.current, 1);
        assert_eq!(
            c.results,
            vec![CycleResult {
                success: true,
                dist: 0.15,
                steps: 8
            }]
        );
    }

    #[test]
    fn a_cycle_that_runs_out_of_time_fails_and_the_next_begins() {
        let mut c = CycleTracker::new(2, params());
        for _ in 0..9 {
            assert_eq!(c.update(0.8, 0.0), Handoff::Continue);
        }
        assert_eq!(c.update(0.8, 0.0), Handoff::Next);
        assert!(!c.results[0].success && c.results[0].dist == 0.8);
        for _ in 0..2 {
            c.update(0.05, 0.0);
        }
        assert_eq!(c.update(0.05, 0.0), Handoff::Done);
        assert!(c.done() && c.results[1].success);
        assert_eq!(c.update(0.0, 0.0), Handoff::Done);
    }
}
