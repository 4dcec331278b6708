//! The Hierarchical RL baseline's five low-level skills (paper Sec. 4.2): walk, reach-and-grasp,
//! lift, obstacle-aware carry and place-and-release, switched by a finite-state machine that reads
//! the privileged state. Each skill has its own reward (the task terms that are its business) and
//! its own termination (it ends when the machine moves on from it: forward is its success, back —
//! the object slipped — its failure). All pure functions over plain values.

use crate::task::rewards::RewardWeights;
use serde::{Deserialize, Serialize};

/// One low-level skill, in the order a cycle needs them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Skill {
    Walk,
    ReachGrasp,
    Lift,
    Carry,
    Place,
}

impl Skill {
    pub const ALL: [Skill; 5] = [
        Skill::Walk,
        Skill::ReachGrasp,
        Skill::Lift,
        Skill::Carry,
        Skill::Place,
    ];

    /// Position in [`Skill::ALL`] (the one-hot the policy reads).
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Skill::Walk => "walk",
            Skill::ReachGrasp => "reach-grasp",
            Skill::Lift => "lift",
            Skill::Carry => "carry",
            Skill::Place => "place",
        }
    }

    /// The skill's own reward: the task weights with every term that is not its business set to
    /// 0. Walking: locomotion and facing; reach-and-grasp: hands and facing; lift: hands and
    /// lift; carry: hands and carry (its obstacle awareness comes from the obstacle map it sees);
    /// place-and-release: place and release-and-retreat. Power, being alive, the cycle's success
    /// and imitation count for every skill.
    pub fn reward_weights(self, all: &RewardWeights) -> RewardWeights {
        let keep = |on: bool, w: f32| if on { w } else { 0.0 };
        let s = self;
        RewardWeights {
            locomotion: keep(s == Skill::Walk, all.locomotion),
            facing: keep(matches!(s, Skill::Walk | Skill::ReachGrasp), all.facing),
            hands: keep(
                matches!(s, Skill::ReachGrasp | Skill::Lift | Skill::Carry),
                all.hands,
            ),
            lift: keep(s == Skill::Lift, all.lift),
            carry: keep(s == Skill::Carry, all.carry),
            place: keep(s == Skill::Place, all.place),
            release_retreat: keep(s == Skill::Place, all.release_retreat),
            ..*all
        }
    }
}

/// The switching thresholds of the skill machine (a completed skill is paid
/// `RewardWeights::skill`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SkillConfig {
    /// Root within this horizontal distance of the object (m): reach-and-grasp takes over from
    /// walking (the environment's reach distance).
    pub reach_distance: f32,
    /// Both hands within this distance of the object's surface (m) count as holding it.
    pub grasp_distance: f32,
    /// A held object risen this far above its start (m) is lifted: carrying takes over.
    pub lifted_height: f32,
    /// A held object within this horizontal distance of its goal (m): place-and-release takes
    /// over. A released object within the success radius of its goal stays with it too.
    pub place_distance: f32,
}

impl Default for SkillConfig {
    fn default() -> Self {
        Self {
            reach_distance: 0.6,
            grasp_distance: 0.08,
            lifted_height: 0.15,
            place_distance: 0.5,
        }
    }
}

/// What the skill machine reads of the privileged state, for the current (object, goal) pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkillSituation {
    /// Horizontal root-to-object distance (m).
    pub root_to_object: f32,
    /// Each hand's distance to the object's surface (m).
    pub hands_to_object: [f32; 2],
    /// The object's height above where it started (m).
    pub object_rise: f32,
    /// Horizontal object-to-goal distance (m).
    pub object_to_goal_flat: f32,
    /// Object-to-goal distance in 3-D (m).
    pub object_to_goal: f32,
}

/// The skill the machine hands control to in `s`.
pub fn select(s: &SkillSituation, c: &SkillConfig) -> Skill {
    let held = s.hands_to_object[0].max(s.hands_to_object[1]) <= c.grasp_distance;
    let placed = s.object_to_goal <= crate::task::terminations::SUCCESS_RADIUS;
    if placed || (held && s.object_to_goal_flat <= c.place_distance) {
        Skill::Place
    } else if held && s.object_rise >= c.lifted_height {
        Skill::Carry
    } else if held {
        Skill::Lift
    } else if s.root_to_object <= c.reach_distance {
        Skill::ReachGrasp
    } else {
        Skill::Walk
    }
}

/// How a step ended the acting skill's part of the episode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SkillEnd {
    /// The same skill acts next step.
    Continues,
    /// The machine moved on to a later skill: the acting one succeeded.
    Completed,
    /// The machine went back to an earlier skill (e.g. the object slipped from the hands), or
    /// the cycle handed off to the next pair: the acting skill's part ends without its bonus.
    Left,
}

/// The acting skill's end when the machine picks `next` after `acting` has acted.
pub fn skill_end(acting: Skill, next: Skill) -> SkillEnd {
    match next.cmp(&acting) {
        std::cmp::Ordering::Equal => SkillEnd::Continues,
        std::cmp::Ordering::Greater => SkillEnd::Completed,
        std::cmp::Ordering::Less => SkillEnd::Left,
    }
}

/// The policy's skill input: a one-hot over [`Skill::ALL`].
pub fn one_hot(skill: Skill) -> [f32; 5] {
    let mut v = [0.0; 5];
    v[skill.index()] = 1.0;
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn far() -> SkillSituation {
        SkillSituation {
            root_to_object: 3.0,
            hands_to_object: [2.5, 2.6],
            object_rise: 0.0,
            object_to_goal_flat: 4.0,
            object_to_goal: 4.1,
        }
    }

    #[test]
    fn the_machine_walks_reaches_lifts_carries_and_places_in_turn() {
        let c = SkillConfig::default();
        let mut s = far();
        assert_eq!(select(&s, &c), Skill::Walk);
        s.root_to_object = 0.5;
        assert_eq!(select(&s, &c), Skill::ReachGrasp);
        s.hands_to_object = [0.02, 0.05];
        assert_eq!(select(&s, &c), Skill::Lift);
        s.object_rise = 0.2;
        assert_eq!(select(&s, &c), Skill::Carry);
        s.object_to_goal_flat = 0.4;
        s.object_to_goal = 0.6;
        assert_eq!(select(&s, &c), Skill::Place);
        // Released on the goal: still placing (and retreating), not reaching for it again.
        s.hands_to_object = [0.4, 0.4];
        s.object_to_goal = 0.1;
        assert_eq!(select(&s, &c), Skill::Place);
    }

    #[test]
    fn one_hand_on_the_object_is_not_a_grasp_and_a_dropped_object_is_reached_for_again() {
        let c = SkillConfig::default();
        let mut s = far();
        s.root_to_object = 0.4;
        s.hands_to_object = [0.01, 0.3];
        assert_eq!(select(&s, &c), Skill::ReachGrasp);
        // Dropped on the way, away from the goal: the machine goes back to reaching for it.
        s.hands_to_object = [0.3, 0.3];
        s.object_rise = 0.0;
        s.object_to_goal_flat = 2.0;
        assert_eq!(select(&s, &c), Skill::ReachGrasp);
        // Held near the goal but dropped there, short of it: reached for again.
        s.object_to_goal_flat = 0.45;
        s.object_to_goal = 0.5;
        assert_eq!(select(&s, &c), Skill::ReachGrasp);
    }

    #[test]
    fn forward_completes_a_skill_and_back_leaves_it() {
        assert_eq!(skill_end(Skill::Lift, Skill::Lift), SkillEnd::Continues);
        assert_eq!(
            skill_end(Skill::Walk, Skill::ReachGrasp),
            SkillEnd::Completed
        );
        assert_eq!(skill_end(Skill::Lift, Skill::Place), SkillEnd::Completed);
        assert_eq!(skill_end(Skill::Carry, Skill::ReachGrasp), SkillEnd::Left);
        assert_eq!(skill_end(Skill::Place, Skill::Walk), SkillEnd::Left);
    }

    #[test]
    fn each_skill_is_paid_only_for_its_own_terms() {
        let all = RewardWeights {
            release_retreat: 0.5,
            ..RewardWeights::default()
        };
        let walk = Skill::Walk.reward_weights(&all);
        assert_eq!(walk.locomotion, all.locomotion);
        assert_eq!(walk.facing, all.facing);
        assert_eq!(
            (walk.hands, walk.lift, walk.carry, walk.place),
            (0.0, 0.0, 0.0, 0.0)
        );
        let carry = Skill::Carry.reward_weights(&all);
        assert_eq!((carry.carry, carry.hands), (all.carry, all.hands));
        assert_eq!((carry.locomotion, carry.place, carry.lift), (0.0, 0.0, 0.0));
        let place = Skill::Place.reward_weights(&all);
        assert_eq!((place.place, place.release_retreat), (all.place, 0.5));
        assert_eq!(place.hands, 0.0, "place-and-release is paid to let go");
        for skill in Skill::ALL {
            let w = skill.reward_weights(&all);
            assert_eq!(
                (w.alive, w.power, w.success, w.imitation),
                (all.alive, all.power, all.success, all.imitation),
                "{}",
                skill.name()
            );
            assert_eq!(one_hot(skill).iter().sum::<f32>(), 1.0);
            assert_eq!(one_hot(skill)[skill.index()], 1.0);
        }
    }
}
