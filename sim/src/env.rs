//! The task environment an actor steps: a [`World`] in a benchmark room plus the pieces of the
//! task — observations, reward terms, terminations, cycle switching and the AMP history — wired
//! together. Each piece stays a small pure function in `obs` and `task`.

use crate::gait::{
    aligned_to, base_targets, start_targets, steer, stop_targets, BalanceGains, GaitReference, Rig,
    StartRamp, CONTACT_HEIGHT,
};
use crate::mjcf::{CharacterModel, JointKind};
use crate::motion::demo::DemoMotion;
use crate::motion::retarget::KinematicPose;
use crate::obs::{
    amp_frame, amp_frame_dim, finite_difference_states, obstacle_map, proprioception,
    proprioception_dim, task_observation, AmpHistory, BodyState, HeadingFrame, TASK_OBS_DIM,
};
use crate::task::cycles::{CycleTracker, Handoff, SwitchParams};
use crate::task::rewards::{self, ReleaseRetreat, RewardWeights};
use crate::task::skills::{self, Skill, SkillConfig, SkillEnd, SkillSituation};
use crate::task::terminations::{fall_exempt, fallen, placement_error};
use crate::world::{SimConfig, Snapshot, World};
use lhm_scenes::geometry::Rect;
use lhm_scenes::routes::obstacle_rect;
use lhm_scenes::{Catalogue, Support, Task};
use rapier3d::math::Rotation;
use rapier3d::math::Vector;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvConfig {
    pub weights: RewardWeights,
    pub release_retreat: ReleaseRetreat,
    pub switching: SwitchParams,
    /// AMP frames the discriminator sees.
    pub amp_frames: usize,
    /// Obstacle map: cells per side and cell size (m).
    pub map_cells: usize,
    pub map_cell: f32,
    /// A body other than feet and hands below this height (m) is a fall.
    pub fall_height: f32,
    /// The root (pelvis) below this height (m) is a fall too (early termination as in the AMP
    /// anchors: fallen frames never reach the discriminator).
    pub root_fall_height: f32,
    /// The pelvis, torso or head pressing on furniture or a wall is a fall too: a character
    /// lying across a stool is not up, though the height rules above say so (the fourteenth
    /// session's planner stayed "up" 20 s that way).
    pub fall_on_furniture: bool,
    /// An episode "reached" its object once the root came this close (m, horizontally).
    pub reach_distance: f32,
    /// Probability that an episode starts from a reference-motion frame (reference-state
    /// initialisation, as AMP/ASE/TokenHSI) instead of the task's start pose. Needs the motion
    /// clips on the actor's machine.
    pub demo_start_probability: f32,
    /// Of those demo starts, the fraction whose heading is turned toward the first object
    /// (± `demo_start_yaw_noise`) instead of the task's start yaw. The median object lies 93°
    /// off the start heading, so a walking clip started along it walks away; turned toward the
    /// object, walking on reaches it, and the policy sees from its first iteration the states
    /// where walking pays.
    pub demo_start_toward_object: f32,
    /// Half-width (radians) of the uniform noise on a demo start turned toward the object.
    pub demo_start_yaw_noise: f32,
    /// Time limit of an episode, control steps (truncation, not termination).
    pub max_episode_steps: u32,
    /// Walking and carrying speeds the reward asks for (m/s).
    pub walk_speed: f32,
    pub carry_speed: f32,
    /// Height (m) an object should be lifted to count as lifted.
    pub lift_height: f32,
    /// With `weights.imitation` > 0: seconds after a demo start during which the imitation term
    /// tracks the start's clip (looped clips repeat; others end the track at their end). A demo
    /// start hands the policy a gait that open-loop replay loses within ~1 s (RESULTS.md, fourth
    /// session); tracking it says what to do at every step of that gait, DeepMimic-style.
    pub imitation_seconds: f32,
    /// The Hierarchical RL baseline (`[env.skills]`): a privileged machine picks one of five
    /// skills every step from the state ([`skills::select`]), the policy reads it as a one-hot
    /// after the obstacle map, each step is paid the acting skill's own reward terms, and a
    /// skill's part of the episode ends (terminal for the return, the world goes on) when the
    /// machine moves on from it. `None`: the paper's task reward, no skill input.
    pub skills: Option<SkillConfig>,
    /// A reference gait with balance feedback as the base of the action (`[env.gait]`, off by
    /// default; [`crate::gait`]): every episode starts in the gait, and the policy's action is a
    /// residual on the base's PD targets. The policy reads the gait's phase (sin, cos) after the
    /// obstacle map (and the skill, if any).
    pub gait: Option<GaitConfig>,
    /// Flat empty ground ([`empty_room`]): the task's furniture removed, its walls 30 m away and
    /// its objects 25 m further along x. A training aid for the character's own balance (the
    /// walk's falls without the room's), as the anchors pretrain locomotion on flat ground; the
    /// task's reach and placement terms then measure nothing.
    pub empty_room: bool,
    /// The task's furniture removed ([`without_furniture`]), its walls, start and objects where
    /// the task has them (an object or goal on furniture put on the floor below it): the walk to
    /// the object and its reach, without the furniture a character that cannot yet avoid it
    /// trips over. A training aid between `empty_room` and the task's own room.
    pub clear_furniture: bool,
}

/// The room of `task` without its furniture ([`EnvConfig::clear_furniture`]): walls, start and
/// objects kept; an object or goal that rested on furniture rests on the floor below it.
pub fn without_furniture(task: &Task) -> Task {
    let mut task = task.clone();
    task.obstacles.clear();
    for o in &mut task.objects {
        if o.on != Support::Floor {
            o.on = Support::Floor;
            o.pos[2] = o.size[2] / 2.0;
        }
    }
    for step in &mut task.sequence {
        if step.on != Support::Floor {
            step.on = Support::Floor;
            if let Some(o) = task.objects.iter().find(|o| o.id == step.object) {
                step.goal[2] = o.size[2] / 2.0;
            }
        }
    }
    task
}

/// The room of `task` emptied ([`EnvConfig::empty_room`]): no furniture, walls at ±30 m, every
/// object moved 25 m along +x (a heading toward the first object stays a heading).
pub fn empty_room(task: &Task) -> Task {
    let mut task = task.clone();
    task.obstacles.clear();
    task.room_size = [60.0, 60.0];
    for o in &mut task.objects {
        o.pos[0] += 25.0;
    }
    task
}

/// `[env.gait]`: the residual base.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaitConfig {
    /// The looped clip the gait follows: the first installed clip whose name contains this.
    pub clip: String,
    /// PD target = base + `residual` · action scale · action, per DoF (DReCon's residual).
    pub residual: f32,
    /// Per-joint factors on `residual`: a DoF whose name contains a key acts with `residual` ×
    /// that factor (the longest key it contains wins), e.g. `{ shoulder = 0.0, elbow = 0.0 }`
    /// leaves the arms to the clip and the base. Empty (the default): every DoF at `residual`.
    /// A key no DoF's name contains is an error when the run starts ([`GaitConfig::check`]).
    pub residual_joints: std::collections::BTreeMap<String, f32>,
    /// Feed-forward on the base's joint targets (radians), per DoF named exactly: one value for
    /// the whole cycle or one per control step of it, added to the clip's angles
    /// ([`crate::gait::GaitReference::with_angle_offsets`]; the walk, its start ramp and its stop
    /// all take the clip's angles with them). For joints the servo holds off the clip: the
    /// fifty-fifth session measured the arms 7-9° and the knees 10-14° off it while walking, and a
    /// discriminator told the walk from the clips on posture alone. `gait_ilc_probe` writes
    /// these. Empty (the default): the clip's angles.
    pub angle_offsets: std::collections::BTreeMap<String, Vec<f32>>,
    /// Hip yaw (radians) per radian of heading error toward the current object, at most
    /// `steer_max` either way.
    pub steer_gain: f32,
    pub steer_max: f32,
    /// Once the root comes this close (m, horizontally) to the current object the base stops
    /// walking: its targets become the neutral standing pose (zero joint angles; with a
    /// `[env.gait.stop]` ramp, after it) for the rest of the episode, and the phase reads as
    /// zeros. 0: never stop.
    pub stop_distance: f32,
    /// When the base, once within `stop_distance`, stops: at once (`distance`, the default), or
    /// walking on to the reference's next footfall (`footfall`) or until both feet are on the
    /// ground (`feet-down`), at most half a cycle later ([`stop_now`]). A stop at once freezes
    /// the walk wherever it is in the cycle, often on one foot mid-swing.
    pub stop_on: StopOn,
    /// After the stop the imitation term tracks the neutral standing pose (a fresh world's,
    /// moved onto the character's heading and ground position, at rest) instead of paying 0:
    /// the stand gets the dense shaping toward upright, still and feet under the body that the
    /// walk's tracking gives the walk. Off: only `alive` and the task terms pay for standing.
    pub stand_imitation: bool,
    /// Above 0: a training episode ends this long (s) after the base's stop, truncated (the learner
    /// bootstraps its value), instead of standing on to `max_episode_steps`: in the method the
    /// cycle goes on from the reach to the lift, and a stand of the rest of a 10-s episode is
    /// ~75 % of the agent's AMP windows, which no walking clip looks like (`gait_style_probe`).
    /// 0 (default): no such end. `lhm eval` and `render-rollout` play the whole time limit.
    pub stand_seconds: f32,
    /// Starts this far (m, horizontally) before the first object, heading at it, instead of at
    /// the task's start: episodes about the stop alone. 0: the task's start.
    pub start_distance: f32,
    /// With `start_distance` > 0: the fraction of the actors' episodes that start there; the
    /// others start at the task's start (a walk to the object, then the stop), so a run can
    /// practise the stop without forgetting the walk. `lhm eval` and `render-rollout` always start
    /// at `start_distance` when it is set.
    pub near_start_fraction: f32,
    /// Above `start_distance`: a walking start near the object is drawn instead at a uniform
    /// distance in [`start_distance`, the smaller of this and the way's length
    /// ([`TaskEnv::way_length`])] before the object, on the way from the task's start to it (the
    /// straight line, or the route with `route_lookahead`; so inside the room), heading where
    /// the base aims from there — the long walks a start at rest must make, practised from every
    /// point of the way. 0 (or ≤ `start_distance`): every such start `start_distance` before
    /// the object.
    pub start_distance_max: f32,
    /// Above 0: the base steers along a route planned around the room's other objects (and
    /// furniture, where the room keeps it) to the first object ([`crate::route`]), at the point
    /// this many metres ahead on it, instead of straight at the object; starts in the gait turn
    /// toward that point and `start_distance_max`'s starts lie on the route. 0: straight.
    pub route_lookahead: f32,
    /// The clearance (m) the route keeps from walls, furniture and objects where it can (else
    /// the benchmark validator's 0.25 m).
    pub route_clearance: f32,
    /// The fraction of the actors' episodes that start at rest: the task's own standing start
    /// (still, in the neutral pose) turned toward the first object, the gait running from its
    /// cycle step as in the other starts — the walk must begin without the clip's momentum, as
    /// the task asks. Drawn before `near_start_fraction`; 0: never (`lhm eval --from-rest` and
    /// `render-rollout --from-rest` start every episode so).
    pub rest_start_fraction: f32,
    /// Keep the cycle in time with the character's footfalls ([`GaitReference::advance`]): wait
    /// at most `sync_wait` steps for a swing foot that lands late, jump up to `sync_skip` steps to
    /// the reference's footfall when it lands early — while walking (not during the start ramp
    /// from rest, nor after the stop). 0 and 0 (the default): the plain clock.
    pub sync_wait: usize,
    pub sync_skip: usize,
    /// Above 0: the walk pauses once the root is this far (m, straight) from where the walk last
    /// started, while the object is still at least `bout_min_left` away — the base stops as at
    /// the object (`stop_on`), stands `pause_seconds` and walks off again through the start ramp
    /// (`[env.gait.start]`) as from rest. A long walk becomes a chain of the short ones a trained
    /// policy keeps up: its walk gives way after ~2-3 m while its stop and its start from rest
    /// hold (RESULTS.md, twenty-eighth to thirtieth sessions). 0 (the default): one walk.
    pub bout_distance: f32,
    /// With `bout_distance`: no pause unless the object is at least this far (m) from the root.
    pub bout_min_left: f32,
    /// With `bout_distance`: how long (s) the base stands in a pause before it walks on.
    pub pause_seconds: f32,
    pub gains: BalanceGains,
    /// `[env.gait.start]`: how the base walks off from a start at rest (the default: no ramp,
    /// the walk's targets from the first step).
    pub start: StartRamp,
    /// `[env.gait.stop]`: how the base comes to a stand at `stop_distance` — the start's ramp
    /// run backward ([`crate::gait::stop_targets`]): the walk fades out over `seconds` into the
    /// neutral pose plus the lean terms, which it then holds with `feedback`'s share of the
    /// walk's feedback (the default: no ramp, the neutral pose at once).
    pub stop: StartRamp,
}

impl Default for GaitConfig {
    fn default() -> Self {
        Self {
            clip: "humanoid3d_walk".into(),
            residual: 0.2,
            residual_joints: Default::default(),
            angle_offsets: Default::default(),
            // Steering destabilises the base: at 0.5 rad/rad it fell within ~1 s turning toward
            // a goal 30-60° off; at 0.1 it survives as long as walking straight (gait_probe).
            steer_gain: 0.1,
            steer_max: 0.2,
            stop_distance: 0.0,
            stop_on: StopOn::Distance,
            stand_imitation: false,
            stand_seconds: 0.0,
            start_distance: 0.0,
            near_start_fraction: 1.0,
            start_distance_max: 0.0,
            route_lookahead: 0.0,
            // A walking character's feet swing ~0.2 m either side of its root: 0.25 m (the
            // validator's disc) brushes objects, 0.45 m passes them.
            route_clearance: 0.45,
            rest_start_fraction: 0.0,
            sync_wait: 0,
            sync_skip: 0,
            bout_distance: 0.0,
            bout_min_left: 1.2,
            pause_seconds: 1.0,
            gains: BalanceGains::default(),
            start: StartRamp::default(),
            stop: StartRamp::default(),
        }
    }
}

impl GaitConfig {
    /// This gait as a trained policy is judged and shown (`lhm eval`, `render-rollout`): no
    /// `stand_seconds` early end, the stand played to the time limit — a training episode's early
    /// end is no part of the task.
    pub fn played_to_the_limit(self) -> Self {
        Self {
            stand_seconds: 0.0,
            ..self
        }
    }

    /// The residual's scale on the DoF called `dof`: `residual`, times the factor of the longest
    /// `residual_joints` key the name contains.
    pub fn residual_on(&self, dof: &str) -> f32 {
        self.residual
            * self
                .residual_joints
                .iter()
                .filter(|(key, _)| dof.contains(key.as_str()))
                .max_by_key(|(key, _)| key.len())
                .map_or(1.0, |(_, factor)| *factor)
    }

    /// Refuses `residual_joints` keys that name no DoF of `model` and factors that are not finite.
    pub fn check(&self, model: &CharacterModel) -> Result<(), String> {
        for (key, factor) in &self.residual_joints {
            if !factor.is_finite() {
                return Err(format!(
                    "[env.gait] residual_joints.{key} = {factor}: not a finite number"
                ));
            }
            if !model.dofs.iter().any(|d| d.name.contains(key.as_str())) {
                let names: Vec<&str> = model.dofs.iter().map(|d| d.name.as_str()).collect();
                return Err(format!(
                    "[env.gait] residual_joints.{key}: no DoF's name contains {key:?} (the DoFs: {})",
                    names.join(", ")
                ));
            }
        }
        for (name, values) in &self.angle_offsets {
            crate::gait::angle_offset_dof(model, name, values)?;
        }
        Ok(())
    }
}

/// `[env.gait] stop_on`: when the base stops once within `stop_distance` of the object.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopOn {
    /// At once.
    #[default]
    Distance,
    /// At the gait reference's next footfall (its stance foot changes).
    Footfall,
    /// Once both of the character's feet are on the ground.
    FeetDown,
}

/// Whether a base that came within its stop distance `armed_for` steps ago stops now: at once
/// for [`StopOn::Distance`], else at the first footfall (`footfall`: the reference's; `feet_down`:
/// the character's two feet on the ground), and at the latest after `half_cycle` steps (a
/// stride's length: a missed footfall must not walk the character into the object).
pub fn stop_now(
    stop_on: StopOn,
    armed_for: usize,
    half_cycle: usize,
    footfall: bool,
    feet_down: bool,
) -> bool {
    armed_for >= half_cycle
        || match stop_on {
            StopOn::Distance => true,
            StopOn::Footfall => footfall,
            StopOn::FeetDown => feet_down,
        }
}

/// Whether a gait episode's stand is over: `stand_seconds` > 0 and the base stopped (at step
/// `stopped_at`) at least that long before step `steps`, at `hz` control steps a second.
pub fn stand_over(stopped_at: Option<u32>, steps: u32, stand_seconds: f32, hz: f32) -> bool {
    stand_seconds > 0.0
        && stopped_at.is_some_and(|at| steps.saturating_sub(at) as f32 >= stand_seconds * hz)
}

/// The gait an episode runs: its cycle and where in it the next step is.
#[derive(Clone, Debug)]
struct GaitRun {
    reference: Arc<GaitReference>,
    /// The residual's scale on each DoF ([`GaitConfig::residual_on`]), worked out once when the
    /// gait starts rather than by name on every control step.
    residual: Vec<f32>,
    step: usize,
    /// The episode's step count when the gait came within `stop_distance` of the object (it
    /// stops then or at the footfall `stop_on` waits for).
    armed_at: Option<u32>,
    /// The gait stopped ([`stop_now`]) and stands: from then on, or to the end of a pause.
    stopped: bool,
    /// The episode's step count when it stopped (the stop ramp's clock).
    stopped_at: u32,
    /// Started at rest: [`StartRamp`] ramps the base in from step `started_at` (a rest start is
    /// made on a fresh environment: 0; a walk on after a pause: the step it walked on).
    from_rest: bool,
    started_at: u32,
    /// Where (horizontally) the current walk started: the bout's origin (`bout_distance`).
    walk_from: Option<Vector>,
    /// The current stop is a pause (`bout_distance`): the base walks on `pause_seconds` after it.
    pausing: bool,
    /// Steps the cycle has waited in a row for a late footfall (`sync_wait`).
    waited: usize,
}

impl GaitRun {
    /// `[env.gait] bout_distance`: once a pause has lasted `pause_seconds`, walk off again as
    /// from rest (the start ramp from step `steps`, the next bout measured from `root`).
    fn walk_on_after_pause(
        &mut self,
        config: &GaitConfig,
        steps: u32,
        hz: f32,
        root: Option<Vector>,
    ) {
        if self.pausing && steps.saturating_sub(self.stopped_at) as f32 >= config.pause_seconds * hz
        {
            self.stopped = false;
            self.pausing = false;
            self.armed_at = None;
            self.from_rest = true;
            self.started_at = steps;
            self.walk_from = root;
        }
        if self.walk_from.is_none() {
            self.walk_from = root;
        }
    }

    /// `[env.gait] bout_distance`: a walking base with no stop armed arms a pause (it stops as
    /// `stop_on` says) once `root` is `bout_distance` from where the walk started and the object
    /// is still `left` ≥ `bout_min_left` m away.
    fn arm_pause(&mut self, config: &GaitConfig, steps: u32, root: Option<Vector>, left: f32) {
        let walked = root
            .zip(self.walk_from)
            .map_or(0.0, |(r, from)| (r - from).length());
        if self.armed_at.is_none()
            && config.bout_distance > 0.0
            && walked >= config.bout_distance
            && left >= config.bout_min_left
        {
            self.armed_at = Some(steps);
            self.pausing = true;
        }
    }
}

impl Default for EnvConfig {
    fn default() -> Self {
        Self {
            weights: RewardWeights::default(),
            release_retreat: ReleaseRetreat::default(),
            switching: SwitchParams::default(),
            // IsaacGymEnvs HumanoidAMP's numAMPObsSteps: 2 (a 10-frame window let the
            // discriminator win within ~20 iterations).
            amp_frames: 2,
            map_cells: 8,
            map_cell: 0.25,
            fall_height: 0.15,
            root_fall_height: 0.4,
            fall_on_furniture: true,
            reach_distance: 0.6,
            demo_start_probability: 0.0,
            demo_start_toward_object: 0.0,
            demo_start_yaw_noise: 0.5,
            max_episode_steps: 1200,
            // The demo walks are ~1 m/s; 1.5 m/s asked for a gait no clip shows.
            walk_speed: 1.0,
            carry_speed: 1.0,
            lift_height: 0.3,
            imitation_seconds: 3.0,
            skills: None,
            gait: None,
            empty_room: false,
            clear_furniture: false,
        }
    }
}

impl RewardTerms {
    /// Each term times its weight, by name (their sum is the step's task reward).
    pub fn weighted(&self, w: &RewardWeights) -> [(&'static str, f32); 13] {
        [
            ("locomotion", w.locomotion * self.locomotion),
            ("facing", w.facing * self.facing),
            ("hands", w.hands * self.hands),
            ("lift", w.lift * self.lift),
            ("carry", w.carry * self.carry),
            ("place", w.place * self.place),
            ("power", w.power * self.power),
            ("release_retreat", w.release_retreat * self.release_retreat),
            ("success", w.success * self.success),
            ("alive", w.alive * self.alive),
            ("imitation", w.imitation * self.imitation),
            ("skill", w.skill * self.skill),
            ("assist", w.assist * self.assist),
        ]
    }
}

/// Each task reward term of a step, before weighting (for logging).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RewardTerms {
    pub imitation: f32,
    pub locomotion: f32,
    pub hands: f32,
    pub lift: f32,
    pub carry: f32,
    pub place: f32,
    pub power: f32,
    pub release_retreat: f32,
    pub facing: f32,
    /// 1 on the step a pair is handed off within the success radius.
    pub success: f32,
    /// 1 on every step that does not end in a fall.
    pub alive: f32,
    /// 1 on the step the skill machine moves on from the acting skill to a later one.
    pub skill: f32,
    /// The upright assist's effort over the step ([`rewards::assist_effort`], ≤ 0).
    pub assist: f32,
}

#[derive(Clone, Debug)]
pub struct StepResult {
    pub reward: f32,
    pub terms: RewardTerms,
    /// Terminal: fell, physics invalid, or every pair handed off.
    pub done: bool,
    /// Time limit reached (bootstrap from the value).
    pub truncated: bool,
    pub fell: bool,
    /// The NaN/explosion guard tripped: this step's data must not be used.
    pub physics_invalid: bool,
    pub handoff: Handoff,
    /// The weights this step's reward was paid with (the acting skill's under the skill
    /// machine, else the configuration's).
    pub weights: RewardWeights,
    /// Under the skill machine: the acting skill's part of the episode ended on this step
    /// (terminal for its return; the episode itself goes on unless `done`).
    pub skill_ended: bool,
}

pub struct TaskEnv {
    pub model: CharacterModel,
    pub task: Task,
    pub config: EnvConfig,
    pub world: World,
    pub cycles: CycleTracker,
    amp: AmpHistory,
    steps: u32,
    /// Footprints and heights of the static obstacles, for the obstacle map.
    obstacles: Vec<(Rect, f32)>,
    exempt: Vec<bool>,
    /// Pelvis, torso and head: resting on furniture is a fall (`fall_on_furniture`).
    trunk: Vec<usize>,
    hands: [usize; 2],
    /// Height of each object at its start, for the lift term.
    start_z: Vec<f32>,
    /// The root came within `reach_distance` of the current object.
    pub reached: bool,
    /// Body poses at the previous control step: AMP velocities are backward differences.
    prev_bodies: Vec<BodyState>,
    /// The episode started from a reference-motion frame.
    pub demo_start: bool,
    /// After a demo start with the imitation term on: entry k is where the clip puts every body
    /// after control step k + 1, placed as the start placed the character.
    reference: Arc<Vec<Vec<BodyState>>>,
    /// Feet and hands, for the imitation term.
    end_effectors: Vec<usize>,
    /// With `[env.gait]`: the legs the gait's feedback drives (`None` for a character without
    /// them: no gait), and the gait this episode runs (after [`Self::start_gait`]).
    rig: Option<Rig>,
    gait: Option<GaitRun>,
    /// With `[env.gait] route_lookahead`: the planned walk to the first object.
    route: Option<Arc<Vec<[f32; 2]>>>,
    /// The fresh world's body states (the neutral pose, standing at rest): with `[env.gait]
    /// stand_imitation`, the imitation target after the stop.
    standing: Vec<BodyState>,
}

/// Snapshot of a whole environment: world, cycle state, AMP history, counters.
#[derive(Clone)]
pub struct EnvSnapshot {
    world: Snapshot,
    cycles: CycleTracker,
    amp: AmpHistory,
    steps: u32,
    prev_bodies: Vec<BodyState>,
    reached: bool,
    demo_start: bool,
    reference: Arc<Vec<Vec<BodyState>>>,
    gait: Option<GaitRun>,
}

impl TaskEnv {
    pub fn new(
        model: &CharacterModel,
        task: &Task,
        catalogue: &Catalogue,
        sim: SimConfig,
        config: EnvConfig,
    ) -> Self {
        let emptied;
        let task = if config.empty_room {
            emptied = empty_room(task);
            &emptied
        } else if config.clear_furniture {
            emptied = without_furniture(task);
            &emptied
        } else {
            task
        };
        let world = World::with_task(model, sim, task, catalogue);
        let exempt = fall_exempt(model);
        let hands = [
            model.body_index("left_hand").unwrap_or(0),
            model.body_index("right_hand").unwrap_or(0),
        ];
        let rig = config.gait.as_ref().and_then(|_| Rig::new(model));
        let route = config
            .gait
            .as_ref()
            .filter(|g| g.route_lookahead > 0.0)
            .and_then(|g| crate::route::first_walk(task, g.route_clearance))
            .map(Arc::new);
        let mut amp = AmpHistory::new(config.amp_frames, amp_frame_dim(model));
        let prev_bodies = world.body_states();
        amp.push(amp_frame(model, &prev_bodies));
        let standing = if config.gait.as_ref().is_some_and(|g| g.stand_imitation) {
            prev_bodies.clone()
        } else {
            Vec::new()
        };
        Self {
            model: model.clone(),
            task: task.clone(),
            cycles: CycleTracker::new(task.sequence.len(), config.switching),
            amp,
            steps: 0,
            obstacles: task
                .obstacles
                .iter()
                .map(|o| (obstacle_rect(o), o.size[2] as f32))
                .collect(),
            exempt,
            trunk: ["pelvis", "torso", "head"]
                .iter()
                .filter_map(|name| model.body_index(name))
                .collect(),
            hands,
            start_z: task.objects.iter().map(|o| o.pos[2] as f32).collect(),
            config,
            world,
            reached: false,
            prev_bodies,
            demo_start: false,
            reference: Arc::default(),
            end_effectors: ["left_foot", "right_foot", "left_hand", "right_hand"]
                .iter()
                .filter_map(|name| model.body_index(name))
                .collect(),
            rig,
            gait: None,
            route,
            standing,
        }
    }

    /// Reference-state initialisation: the character moves as `clip` of `demo` does at time `t`,
    /// placed at the task's start (root over the start position, heading turned to the start
    /// yaw), with the AMP history filled from the clip's preceding frames. For a fresh
    /// environment (before its first step).
    pub fn start_from_demo(&mut self, demo: &DemoMotion, clip: usize, t: f32) {
        let yaw = self.task.start.yaw as f32;
        self.start_from_demo_heading(demo, clip, t, yaw);
    }

    /// The yaw (radians about +z) from the task's start position toward the first pair's
    /// object, or the start yaw when the task has no pair.
    pub fn yaw_toward_first_object(&self) -> f32 {
        let Some(o) = self.first_object() else {
            return self.task.start.yaw as f32;
        };
        let dx = o.pos[0] - self.task.start.pos[0];
        let dy = o.pos[1] - self.task.start.pos[1];
        if dx.abs() + dy.abs() < 1e-9 {
            return self.task.start.yaw as f32;
        }
        dy.atan2(dx) as f32
    }

    /// The horizontal distance (m) from the task's start to the first pair's object; 0 without
    /// one.
    pub fn first_object_distance(&self) -> f32 {
        self.first_object().map_or(0.0, |o| {
            let dx = o.pos[0] - self.task.start.pos[0];
            let dy = o.pos[1] - self.task.start.pos[1];
            dx.hypot(dy) as f32
        })
    }

    /// The length (m) of the way from the task's start to the first object: along the route
    /// (then straight from its end) with one, else [`Self::first_object_distance`].
    pub fn way_length(&self) -> f32 {
        match (&self.route, self.first_object_xy()) {
            (Some(route), Some(object)) => {
                let along: f32 = route
                    .windows(2)
                    .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
                    .sum();
                let last = route.last().copied().unwrap_or(object);
                along + (object[0] - last[0]).hypot(object[1] - last[1])
            }
            _ => self.first_object_distance(),
        }
    }

    /// The first object's (x, y) as the task places it.
    fn first_object_xy(&self) -> Option<[f32; 2]> {
        self.first_object()
            .map(|o| [o.pos[0] as f32, o.pos[1] as f32])
    }

    /// Where the base aims from `at` on the way to the first object: the route's point
    /// `route_lookahead` ahead ([`crate::route::lookahead`]) with a route, else the object.
    fn way_point_from(&self, at: [f32; 2]) -> Option<[f32; 2]> {
        let object = self.first_object_xy()?;
        match (&self.route, self.config.gait.as_ref()) {
            (Some(route), Some(g)) => Some(crate::route::lookahead(
                route,
                object,
                at,
                g.route_lookahead,
            )),
            _ => Some(object),
        }
    }

    /// The yaw (radians) from `at` toward where the base aims from there
    /// ([`Self::way_point_from`]); [`Self::yaw_toward_first_object`] where that is `at` itself.
    fn yaw_toward_way_from(&self, at: [f32; 2]) -> f32 {
        match self.way_point_from(at) {
            Some(p) if (p[0] - at[0]).abs() + (p[1] - at[1]).abs() > 1e-6 => {
                (p[1] - at[1]).atan2(p[0] - at[0])
            }
            _ => self.yaw_toward_first_object(),
        }
    }

    /// The yaw (radians) from the task's start toward where the base first aims: along the route
    /// with `[env.gait] route_lookahead`, else [`Self::yaw_toward_first_object`].
    pub fn yaw_toward_way(&self) -> f32 {
        if self.route.is_none() {
            // Exactly the straight yaw (computed in f64), as before routes.
            return self.yaw_toward_first_object();
        }
        let start = [self.task.start.pos[0] as f32, self.task.start.pos[1] as f32];
        self.yaw_toward_way_from(start)
    }

    /// The planned walk to the first object (`[env.gait] route_lookahead`), if any.
    pub fn route(&self) -> Option<&[[f32; 2]]> {
        self.route.as_deref().map(Vec::as_slice)
    }

    /// The first pair's object as the task places it.
    fn first_object(&self) -> Option<&lhm_scenes::MovableObject> {
        self.pair(0).and_then(|(i, _, _)| self.task.objects.get(i))
    }

    /// [`Self::start_from_demo`] with the clip's root heading turned to `yaw` instead of the
    /// task's start yaw.
    pub fn start_from_demo_heading(&mut self, demo: &DemoMotion, clip: usize, t: f32, yaw: f32) {
        let at = [self.task.start.pos[0] as f32, self.task.start.pos[1] as f32];
        self.start_from_demo_at(demo, clip, t, at, yaw);
    }

    /// [`Self::start_from_demo_heading`] with the root placed over `at` (x, y) instead of the
    /// task's start position.
    pub fn start_from_demo_at(
        &mut self,
        demo: &DemoMotion,
        clip: usize,
        t: f32,
        at: [f32; 2],
        yaw: f32,
    ) {
        let (states, prev) = demo.start_states(clip, t);
        let Some(root) = states.first() else { return };
        let pose = demo.pose_at(clip, t);
        // The rigid motion taking the clip's root heading frame onto the task's start.
        let clip_yaw = crate::obs::heading_yaw(root.rot);
        let turn = Rotation::from_rotation_z(yaw - clip_yaw);
        let start = Vector::new(at[0], at[1], 0.0);
        let origin = Vector::new(root.pos.x, root.pos.y, 0.0);
        let place = |p: Vector| start + turn * (p - origin);
        let moved = |b: &BodyState| BodyState {
            pos: place(b.pos),
            rot: (turn * b.rot).normalize(),
            linvel: turn * b.linvel,
            angvel: turn * b.angvel,
        };
        let states: Vec<BodyState> = states.iter().map(moved).collect();
        let placed = KinematicPose {
            root_pos: place(pose.root_pos),
            root_rot: (turn * pose.root_rot).normalize(),
            local_rots: pose.local_rots,
        };
        self.world.set_character_state(&placed, &states);
        self.prev_bodies = prev.iter().map(moved).collect();
        self.amp.fill(demo.amp_history_at(clip, t));
        self.demo_start = true;
        if self.config.weights.imitation > 0.0 {
            let dt = 1.0 / self.world.config.control_hz;
            let steps = (self.config.imitation_seconds.max(0.0) / dt).round() as usize;
            self.reference = Arc::new(
                demo.reference_track(clip, t, steps, dt)
                    .iter()
                    .map(|frame| frame.iter().map(moved).collect())
                    .collect(),
            );
        }
    }

    /// Runs the gait from step `step` of `reference`'s cycle: from now on actions are residuals
    /// on its base (a start from the same clip time, [`Self::start_from_demo_heading`], puts the
    /// character where the gait is). `false`, and nothing changes, without `[env.gait]` or for a
    /// character the gait cannot drive.
    pub fn start_gait(&mut self, reference: Arc<GaitReference>, step: usize) -> bool {
        if self.config.gait.is_none() || self.rig.is_none() || reference.is_empty() {
            return false;
        }
        let residual = self
            .config
            .gait
            .as_ref()
            .map(|g| {
                self.model
                    .dofs
                    .iter()
                    .map(|d| g.residual_on(&d.name))
                    .collect()
            })
            .unwrap_or_default();
        self.gait = Some(GaitRun {
            reference,
            residual,
            step,
            armed_at: None,
            stopped: false,
            stopped_at: 0,
            from_rest: false,
            started_at: 0,
            walk_from: None,
            pausing: false,
            waited: 0,
        });
        true
    }

    /// A start in the gait: the character as the gait's clip is at cycle step `step`, placed at
    /// the task's start (or `[env.gait] start_distance` before the first object) and turned to
    /// `yaw`, and the gait running from there ([`Self::start_from_demo_at`] +
    /// [`Self::start_gait`]). `reference` must be a cycle of `demo`'s clips
    /// ([`crate::gait::reference_for`]).
    pub fn start_in_gait(
        &mut self,
        demo: &DemoMotion,
        reference: Arc<GaitReference>,
        step: usize,
        yaw: f32,
    ) -> bool {
        let near = self
            .config
            .gait
            .as_ref()
            .is_some_and(|g| g.start_distance > 0.0);
        self.start_in_gait_where(demo, reference, step, yaw, near)
    }

    /// [`Self::start_in_gait`] at `[env.gait] start_distance` before the first object when
    /// `near` (and that distance is set), else at the task's start.
    pub fn start_in_gait_where(
        &mut self,
        demo: &DemoMotion,
        reference: Arc<GaitReference>,
        step: usize,
        yaw: f32,
        near: bool,
    ) -> bool {
        let Some(config) = self.config.gait.as_ref().filter(|_| self.rig.is_some()) else {
            return false;
        };
        let mut at = [self.task.start.pos[0] as f32, self.task.start.pos[1] as f32];
        if let (Some(o), true) = (self.first_object(), near && config.start_distance > 0.0) {
            // `start_distance` before the first object, on the line the heading points along.
            at = [
                o.pos[0] as f32 - config.start_distance * yaw.cos(),
                o.pos[1] as f32 - config.start_distance * yaw.sin(),
            ];
        }
        self.start_from_demo_at(demo, reference.clip, reference.time(step), at, yaw);
        self.start_gait(reference, step)
    }

    /// [`Self::start_in_gait`] `distance` (m) before the first object along the way from the
    /// task's start to it (`[env.gait] start_distance_max`): on the route with one, else on the
    /// straight line; heading `yaw_offset` off the direction to where the base aims from there.
    /// At the task's start when the way is no longer than `distance` (or there is no object).
    pub fn start_in_gait_on_way(
        &mut self,
        demo: &DemoMotion,
        reference: Arc<GaitReference>,
        step: usize,
        yaw_offset: f32,
        distance: f32,
    ) -> bool {
        if self.config.gait.is_none() || self.rig.is_none() {
            return false;
        }
        let start = [self.task.start.pos[0] as f32, self.task.start.pos[1] as f32];
        let at = match (self.first_object_xy(), &self.route) {
            (Some(object), Some(route)) => {
                crate::route::point_before(route, object, distance).unwrap_or(start)
            }
            (Some(object), None) => {
                crate::route::point_before(&[start], object, distance).unwrap_or(start)
            }
            (None, _) => start,
        };
        let yaw = self.yaw_toward_way_from(at) + yaw_offset;
        self.start_from_demo_at(demo, reference.clip, reference.time(step), at, yaw);
        self.start_gait(reference, step)
    }

    /// [`Self::start_at_rest_in_gait`] when `rest`, else [`Self::start_in_gait`]: the two starts
    /// `lhm eval` and `render-rollout` offer.
    pub fn start_in_gait_from(
        &mut self,
        demo: &DemoMotion,
        reference: Arc<GaitReference>,
        step: usize,
        yaw: f32,
        rest: bool,
    ) -> bool {
        if rest {
            self.start_at_rest_in_gait(reference, step, yaw)
        } else {
            self.start_in_gait(demo, reference, step, yaw)
        }
    }

    /// A start at rest in the gait: the character stands still where the task starts it (the
    /// neutral pose of a freshly built world), turned about its root to `yaw`, and the gait runs
    /// from cycle step `step` ([`Self::start_gait`]). For a fresh environment (before its first
    /// step); `false`, and nothing changes, where [`Self::start_gait`] would refuse.
    pub fn start_at_rest_in_gait(
        &mut self,
        reference: Arc<GaitReference>,
        step: usize,
        yaw: f32,
    ) -> bool {
        if self.config.gait.is_none() || self.rig.is_none() || reference.is_empty() {
            return false;
        }
        let standing = self.world.body_states();
        let Some(root) = standing.first().copied() else {
            return false;
        };
        let turn = Rotation::from_rotation_z(yaw - crate::obs::heading_yaw(root.rot));
        let origin = Vector::new(root.pos.x, root.pos.y, 0.0);
        let turned: Vec<BodyState> = standing
            .iter()
            .map(|b| BodyState {
                pos: origin + turn * (b.pos - origin),
                rot: (turn * b.rot).normalize(),
                linvel: Vector::ZERO,
                angvel: Vector::ZERO,
            })
            .collect();
        let pose = KinematicPose {
            root_pos: turned[0].pos,
            root_rot: turned[0].rot,
            local_rots: vec![Rotation::IDENTITY; self.model.bodies.len()],
        };
        self.world.set_character_state(&pose, &turned);
        self.amp.fill(vec![amp_frame(&self.model, &turned)]);
        self.prev_bodies = turned;
        let started = self.start_gait(reference, step);
        if let Some(run) = self.gait.as_mut().filter(|_| started) {
            run.from_rest = true;
        }
        started
    }

    /// The joint angles the gait's reference holds at its next step (the neutral pose's zeros once
    /// it has stopped); `None` without a gait.
    pub fn gait_reference_angles(&self) -> Option<Vec<f32>> {
        let run = self.gait.as_ref()?;
        Some(if run.stopped {
            vec![0.0; self.model.dofs.len()]
        } else {
            run.reference.at(run.step).1.to_vec()
        })
    }

    /// What the imitation term tracks now while the gait walks: the reference's frame for the
    /// current step moved onto the character's heading and ground position ([`aligned_to`]);
    /// `None` without a gait or once it has stopped. For probes of how closely the walk follows
    /// the clip.
    pub fn gait_imitation_target(&self) -> Option<Vec<BodyState>> {
        let run = self.gait.as_ref().filter(|run| !run.stopped)?;
        let states = self.world.body_states();
        let root = states.first()?;
        Some(aligned_to(run.reference.at(run.step).0, root))
    }

    /// Whether this episode's gait has stopped (the character stands from then on, or to the end
    /// of a pause with `bout_distance`); false without a gait.
    pub fn gait_stopped(&self) -> bool {
        self.gait.as_ref().is_some_and(|g| g.stopped)
    }

    /// Whether the last step's targets were the gait's walk-off from rest (the first
    /// `[env.gait.start] seconds` of a start at rest or of a walk on after a pause), and it had not
    /// stopped; false without a gait or on a walking start.
    pub fn gait_ramping(&self) -> bool {
        let (Some(run), Some(config)) = (&self.gait, &self.config.gait) else {
            return false;
        };
        // `gait_targets` runs before the step count moves on: the last step's clock is one back.
        let elapsed = self.steps.saturating_sub(1).saturating_sub(run.started_at) as f32
            / self.world.config.control_hz;
        !run.stopped && run.from_rest && elapsed < config.start.seconds
    }

    /// Whether a gait runs this episode (walking or stopped).
    pub fn gait_running(&self) -> bool {
        self.gait.is_some()
    }

    /// [`stand_over`] for this episode's gait and `[env.gait] stand_seconds`.
    fn stand_is_over(&self) -> bool {
        let (Some(run), Some(config)) = (&self.gait, &self.config.gait) else {
            return false;
        };
        stand_over(
            (run.stopped && !run.pausing).then_some(run.stopped_at),
            self.steps,
            config.stand_seconds,
            self.world.config.control_hz,
        )
    }

    /// The gait's phase in its cycle, [0, 1), while one runs and walks.
    pub fn gait_phase(&self) -> Option<f32> {
        self.gait
            .as_ref()
            .filter(|g| !g.stopped)
            .map(|g| g.reference.phase(g.step))
    }

    pub fn obs_dim(model: &CharacterModel, config: &EnvConfig) -> usize {
        proprioception_dim(model)
            + TASK_OBS_DIM
            + config.map_cells * config.map_cells
            + if config.skills.is_some() {
                Skill::ALL.len()
            } else {
                0
            }
            + if config.gait.is_some() { 2 } else { 0 }
    }

    pub fn amp_dim(model: &CharacterModel, config: &EnvConfig) -> usize {
        amp_frame_dim(model) * config.amp_frames
    }

    /// Pair `k`'s object index, its goal, and the object's half extents.
    fn pair(&self, k: usize) -> Option<(usize, Vector, Vector)> {
        let step = self.task.sequence.get(k)?;
        let i = self.task.object_index(&step.object)?;
        let s = self.task.objects[i].size;
        Some((
            i,
            Vector::new(
                step.goal[0] as f32,
                step.goal[1] as f32,
                step.goal[2] as f32,
            ),
            Vector::new(s[0] as f32, s[1] as f32, s[2] as f32) * 0.5,
        ))
    }

    fn current(&self) -> Option<(usize, Vector, Vector)> {
        self.pair(self.cycles.current)
    }

    fn object_state(&self, i: usize) -> BodyState {
        let b = &self.world.state.bodies[self.world.room.objects[i]];
        BodyState {
            pos: b.position().translation,
            rot: b.position().rotation,
            linvel: b.linvel(),
            angvel: b.angvel(),
        }
    }

    /// Proprioception, then the current pair (after the last pair: the last one again), then the
    /// obstacle map.
    pub fn observation(&self) -> Vec<f32> {
        let bodies = self.world.body_states();
        let mut obs = proprioception(&bodies);
        // After the last handoff the last pair stays in view.
        let last = self.task.sequence.len().saturating_sub(1);
        let pair = self.pair(self.cycles.current.min(last));
        match pair {
            Some((i, goal, half)) => obs.extend(task_observation(
                &bodies[0],
                &self.object_state(i),
                half,
                goal,
            )),
            None => obs.extend(std::iter::repeat_n(0.0, TASK_OBS_DIM)),
        }
        obs.extend(obstacle_map(
            &bodies[0],
            &self.obstacles,
            self.config.map_cells,
            self.config.map_cell,
        ));
        if self.config.skills.is_some() {
            let skill = self.skill_at(&bodies).unwrap_or(Skill::Walk);
            obs.extend(skills::one_hot(skill));
        }
        if self.config.gait.is_some() {
            // Zeros when no gait runs (a start outside the gait).
            let (sin, cos) = self
                .gait_phase()
                .map_or((0.0, 0.0), |p| (std::f32::consts::TAU * p).sin_cos());
            obs.extend([sin, cos]);
        }
        obs
    }

    /// What the skill machine reads in `bodies` (this world's body states) for the current pair
    /// (after the last handoff, the last pair).
    fn skill_situation(&self, bodies: &[BodyState]) -> Option<SkillSituation> {
        let last = self.task.sequence.len().saturating_sub(1);
        let (i, goal, half) = self.pair(self.cycles.current.min(last))?;
        let obj = self.object_state(i);
        let root = bodies.first()?;
        let flat = |v: Vector| Vector::new(v.x, v.y, 0.0).length();
        let hand = |k: usize| {
            let p = bodies[self.hands[k]].pos;
            rewards::distance_to_box(obj.rot.inverse() * (p - obj.pos), half)
        };
        Some(SkillSituation {
            root_to_object: flat(obj.pos - root.pos),
            hands_to_object: [hand(0), hand(1)],
            object_rise: obj.pos.z - self.start_z[i],
            object_to_goal_flat: flat(goal - obj.pos),
            object_to_goal: placement_error(obj.pos, goal),
        })
    }

    /// The skill the machine picks in `bodies`; `None` without `[env.skills]` or a pair.
    fn skill_at(&self, bodies: &[BodyState]) -> Option<Skill> {
        let config = self.config.skills.as_ref()?;
        Some(skills::select(&self.skill_situation(bodies)?, config))
    }

    /// The skill the machine picks now (`None` without `[env.skills]`).
    pub fn current_skill(&self) -> Option<Skill> {
        // Checked first: without the machine a step should not pay for the body states.
        self.config.skills.as_ref()?;
        self.skill_at(&self.world.body_states())
    }

    /// The AMP frame the environment would record for its current state (velocities as backward
    /// differences from the previous control step's poses).
    pub fn current_amp_frame(&self) -> Vec<f32> {
        let dt = 1.0 / self.world.config.control_hz;
        let now = self.world.body_states();
        amp_frame(
            &self.model,
            &finite_difference_states(&self.prev_bodies, &now, dt),
        )
    }

    /// The discriminator's input for the latest step.
    pub fn amp_features(&self) -> Vec<f32> {
        self.amp.features()
    }

    /// PD targets for an action while a gait runs: the gait's base, turned toward the current
    /// object, plus the action as a residual (within each joint's range); the gait moves on a
    /// step. `None` when no gait runs.
    fn gait_targets(&mut self, action: &[f32]) -> Option<Vec<f32>> {
        let now = self.world.body_states();
        let last = self.task.sequence.len().saturating_sub(1);
        let current = self.cycles.current.min(last);
        // The current object in the root's heading frame (after the last handoff, the last one).
        let object = self
            .pair(current)
            .zip(now.first())
            .map(|((i, _, _), root)| {
                HeadingFrame::of(root).vector(self.object_state(i).pos - root.pos)
            });
        // Where the base steers: along the route on the way to the first object, else the object.
        let aim = match (&self.route, self.config.gait.as_ref(), self.pair(current)) {
            (Some(route), Some(g), Some((i, _, _))) if current == 0 => now.first().map(|root| {
                let o = self.object_state(i).pos;
                let p = crate::route::lookahead(
                    route,
                    [o.x, o.y],
                    [root.pos.x, root.pos.y],
                    g.route_lookahead,
                );
                HeadingFrame::of(root).vector(Vector::new(p[0], p[1], root.pos.z) - root.pos)
            }),
            _ => object,
        };
        let (run, rig, config) = (
            self.gait.as_mut()?,
            self.rig.as_ref()?,
            self.config.gait.as_ref()?,
        );
        let hz = self.world.config.control_hz;
        let root = now.first().map(|r| Vector::new(r.pos.x, r.pos.y, 0.0));
        run.walk_on_after_pause(config, self.steps, hz, root);
        if let Some(to) = object.filter(|_| !run.stopped) {
            let left = Vector::new(to.x, to.y, 0.0).length();
            if run.armed_at.is_none() && left < config.stop_distance {
                run.armed_at = Some(self.steps);
            }
            run.arm_pause(config, self.steps, root, left);
            if let Some(armed) = run.armed_at {
                if stop_now(
                    config.stop_on,
                    self.steps.saturating_sub(armed) as usize,
                    run.reference.len() / 2,
                    run.reference.footfall(rig, run.step),
                    rig.feet_down(&now, CONTACT_HEIGHT),
                ) {
                    run.stopped = true;
                    run.stopped_at = self.steps;
                }
            }
        }
        let (reference_now, angles) = run.reference.at(run.step);
        let ramp_elapsed = self.steps.saturating_sub(run.started_at) as f32 / hz;
        let mut targets = match (run.stopped, run.from_rest) {
            (true, _) => stop_targets(
                rig,
                &config.gains,
                &config.stop,
                self.steps.saturating_sub(run.stopped_at) as f32 / hz,
                &now,
                reference_now,
                angles,
            ),
            (false, true) => start_targets(
                rig,
                &config.gains,
                &config.start,
                ramp_elapsed,
                &now,
                reference_now,
                angles,
            ),
            (false, false) => base_targets(rig, &config.gains, &now, reference_now, angles),
        };
        if let (Some(to), false) = (aim, run.stopped) {
            let error = to.y.atan2(to.x);
            steer(
                rig,
                &mut targets,
                reference_now,
                config.steer_gain * error,
                config.steer_max,
            );
        }
        let character = &self.world.character;
        for (i, (t, d)) in targets.iter_mut().zip(&self.model.dofs).enumerate() {
            let a = action
                .get(i)
                .copied()
                .filter(|a| a.is_finite())
                .unwrap_or(0.0);
            let scale = run.residual.get(i).copied().unwrap_or(config.residual);
            *t = (*t + scale * character.action_scale[i] * a)
                .clamp(d.range[0] as f32, d.range[1] as f32);
        }
        // The footfalls keep the clock only while the character walks: standing before the start
        // ramp is over or after the stop both feet are down, which `advance` would read as an
        // early landing and jump the cycle on every step.
        let ramping = run.from_rest && ramp_elapsed < config.start.seconds;
        run.step = if run.stopped || ramping {
            run.step + 1
        } else {
            run.reference.advance(
                rig,
                run.step,
                &now,
                &mut run.waited,
                config.sync_wait,
                config.sync_skip,
            )
        };
        Some(targets)
    }

    pub fn step(&mut self, action: &[f32]) -> StepResult {
        let acting = self.current_skill();
        let targets = match self.gait_targets(action) {
            Some(targets) => targets,
            None => self.world.character.targets(action),
        };
        let ok = self.world.step_targets(&targets);
        self.steps += 1;
        if !ok {
            return StepResult {
                reward: 0.0,
                terms: RewardTerms::default(),
                done: true,
                truncated: false,
                fell: false,
                physics_invalid: true,
                handoff: Handoff::Done,
                weights: self.config.weights,
                skill_ended: false,
            };
        }
        let bodies = self.world.body_states();
        let dt = 1.0 / self.world.config.control_hz;
        let moving = finite_difference_states(&self.prev_bodies, &bodies, dt);
        self.amp.push(amp_frame(&self.model, &moving));
        self.prev_bodies.clone_from(&bodies);
        let mut terms = RewardTerms {
            power: self.power(&bodies, &targets),
            assist: rewards::assist_effort(self.world.assist_torque, self.world.assist_force),
            imitation: self.imitation(&bodies),
            ..RewardTerms::default()
        };
        let mut handoff = Handoff::Done;
        if let Some((i, goal, half)) = self.current() {
            let obj = self.object_state(i);
            let root = &bodies[0];
            let to_local = |p: Vector| obj.rot.inverse() * (p - obj.pos);
            let (lh, rh) = (bodies[self.hands[0]].pos, bodies[self.hands[1]].pos);
            let w = &self.config;
            terms.locomotion =
                rewards::locomotion(root.pos, root.linvel, obj.pos, w.walk_speed, 0.6);
            terms.facing = rewards::facing(root.pos, root.rot * Vector::X, obj.pos, 0.6);
            terms.hands = rewards::hands_to_object(to_local(lh), to_local(rh), half, 20.0);
            terms.lift = rewards::lift(obj.pos.z, self.start_z[i], w.lift_height);
            terms.carry = rewards::carry(obj.pos, obj.linvel, goal, w.carry_speed, 0.3);
            terms.place = rewards::place(obj.pos, goal, 10.0);
            let d_goal = placement_error(obj.pos, goal);
            let d_root = (Vector::new(root.pos.x, root.pos.y, 0.0)
                - Vector::new(obj.pos.x, obj.pos.y, 0.0))
            .length();
            let hand_d = |h: Vector| rewards::distance_to_box(to_local(h), half);
            terms.release_retreat = rewards::release_and_retreat(
                &w.release_retreat,
                d_root,
                hand_d(lh),
                hand_d(rh),
                d_goal,
            );
            self.reached |= d_root < w.reach_distance;
            let before = self.cycles.results.len();
            handoff = self.cycles.update(d_goal, obj.linvel.length());
            if self.cycles.results.len() > before
                && self.cycles.results.last().is_some_and(|r| r.success)
            {
                terms.success = 1.0;
            }
        }
        let heights: Vec<f32> = bodies.iter().map(|b| b.pos.z).collect();
        let fell = fallen(&heights, &self.exempt, self.config.fall_height)
            || bodies[0].pos.z < self.config.root_fall_height
            || (self.config.fall_on_furniture && self.trunk_on_furniture());
        terms.alive = if fell { 0.0 } else { 1.0 };
        let mut weights = self.config.weights;
        let mut skill_ended = false;
        if let Some(acting) = acting {
            weights = acting.reward_weights(&self.config.weights);
            // A handoff to the next pair leaves the acting skill whatever the machine says of
            // the new pair (its walk starts a new part).
            let next = if handoff == Handoff::Next {
                None
            } else {
                self.skill_at(&bodies)
            };
            let end = next.map_or(SkillEnd::Left, |next| skills::skill_end(acting, next));
            terms.skill = if end == SkillEnd::Completed { 1.0 } else { 0.0 };
            skill_ended = end != SkillEnd::Continues;
        }
        let reward = terms.weighted(&weights).iter().map(|(_, v)| v).sum();
        let done = fell || handoff == Handoff::Done;
        StepResult {
            reward,
            terms,
            done,
            truncated: !done
                && (self.steps >= self.config.max_episode_steps || self.stand_is_over()),
            fell,
            physics_invalid: false,
            handoff,
            weights,
            skill_ended,
        }
    }

    /// Whether the pelvis, torso or head presses on furniture or a wall.
    fn trunk_on_furniture(&self) -> bool {
        let touching = self.world.furniture_contacts();
        self.trunk
            .iter()
            .any(|&b| touching.get(b).copied().unwrap_or(false))
    }

    /// The imitation term after a step. While a gait walks: its reference's frame for now, moved
    /// onto the character's heading and ground position ([`aligned_to`]), so the walk is tracked
    /// wherever the steering took it (DeepMimic's phase-indexed target, DReCon's kinematic
    /// reference). After the gait's stop: the standing pose so moved with `stand_imitation`,
    /// else 0. Otherwise the demo start's track, in the world. 0 when the weight is 0.
    fn imitation(&self, bodies: &[BodyState]) -> f32 {
        if self.config.weights.imitation == 0.0 {
            return 0.0;
        }
        if let Some(run) = self.gait.as_ref() {
            let Some(root) = bodies.first() else {
                return 0.0;
            };
            if run.stopped {
                // Empty unless `stand_imitation` (the constructor keeps the pose only then).
                if self.standing.is_empty() {
                    return 0.0;
                }
                let target = aligned_to(&self.standing, root);
                return rewards::imitation(bodies, &target, &self.end_effectors);
            }
            let target = aligned_to(run.reference.at(run.step).0, root);
            return rewards::imitation(bodies, &target, &self.end_effectors);
        }
        self.reference
            .get(self.steps as usize - 1)
            .map_or(0.0, |r| rewards::imitation(bodies, r, &self.end_effectors))
    }

    /// PD torques the servos apply (from the same error the drive uses), times joint velocities.
    fn power(&self, bodies: &[BodyState], targets: &[f32]) -> f32 {
        let mut torques = Vec::with_capacity(self.model.dofs.len());
        let mut velocities = Vec::with_capacity(self.model.dofs.len());
        for (i, body) in self.model.bodies.iter().enumerate() {
            let Some(p) = body.parent else { continue };
            let (rel, relvel) = crate::obs::joint_state(&bodies[p], &bodies[i]);
            match &body.joint {
                JointKind::Hinge { dof } => {
                    let d = &self.model.dofs[*dof];
                    let axis = Vector::from_array(d.axis.map(|a| a as f32));
                    let q = crate::obs::twist_angle(rel, axis);
                    let qd = relvel.dot(axis);
                    let limit = d.torque_limit as f32;
                    torques.push(
                        (d.kp as f32 * (targets[*dof] - q) - d.kd as f32 * qd).clamp(-limit, limit),
                    );
                    velocities.push(qd);
                }
                JointKind::Ball { dofs } => {
                    let target = crate::character::ball_target(targets, dofs);
                    let e = (target * rel.inverse()).normalize().to_scaled_axis();
                    for k in 0..3 {
                        let d = &self.model.dofs[dofs[k]];
                        let limit = d.torque_limit as f32;
                        torques.push(
                            (d.kp as f32 * e[k] - d.kd as f32 * relvel[k]).clamp(-limit, limit),
                        );
                        velocities.push(relvel[k]);
                    }
                }
                JointKind::Free | JointKind::Fixed => {}
            }
        }
        rewards::power_penalty(&torques, &velocities)
    }

    /// Placement error (m) of every pair attempted so far: the handed-off pairs' errors at their
    /// handoff, then the current pair's error now (an episode cut short still reports it).
    pub fn placement_errors(&self) -> Vec<f32> {
        let mut out: Vec<f32> = self.cycles.results.iter().map(|r| r.dist).collect();
        if !self.cycles.done() {
            if let Some((i, goal, _)) = self.current() {
                out.push(placement_error(self.object_state(i).pos, goal));
            }
        }
        out
    }

    /// Control steps taken since the episode started.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Placement error (m) of every pair of the task, in order: a handed-off pair's error at its
    /// handoff, any other pair's error now (the current one mid-cycle, later ones where their
    /// objects lie: an episode cut short still scores every pair).
    pub fn pair_errors(&self) -> Vec<f32> {
        (0..self.task.sequence.len())
            .map(|k| match self.cycles.results.get(k) {
                Some(r) => r.dist,
                None => self.pair(k).map_or(f32::NAN, |(i, goal, _)| {
                    placement_error(self.object_state(i).pos, goal)
                }),
            })
            .collect()
    }

    pub fn snapshot(&self) -> EnvSnapshot {
        EnvSnapshot {
            world: self.world.snapshot(),
            cycles: self.cycles.clone(),
            amp: self.amp.clone(),
            steps: self.steps,
            prev_bodies: self.prev_bodies.clone(),
            reached: self.reached,
            demo_start: self.demo_start,
            reference: Arc::clone(&self.reference),
            gait: self.gait.clone(),
        }
    }

    pub fn restore(&mut self, s: &EnvSnapshot) {
        self.world.restore(&s.world);
        self.cycles = s.cycles.clone();
        self.amp = s.amp.clone();
        self.steps = s.steps;
        self.prev_bodies = s.prev_bodies.clone();
        self.reached = s.reached;
        self.demo_start = s.demo_start;
        self.reference = Arc::clone(&s.reference);
        self.gait = s.gait.clone();
    }
}
