//! The imitation term's pose error (`gait_tracking_probe`, `gait_ilc_probe`). Included with
//! `#[path]`; not an example of its own.
use lhm_sim::obs::BodyState;
use lhm_sim::CharacterModel;

/// The imitation term's pose error while walking: per step, the sum over bodies of the squared
/// angle between the character's and the aligned reference's rotation, taken in the world (as
/// `rewards::imitation` takes it) and per joint (child relative to parent, DeepMimic's pose
/// reward), and the pose part `exp(-2 Σ)` each gives.
#[derive(Default)]
pub struct PoseError {
    pub steps: usize,
    pub world: f64,
    pub joint: f64,
    pub world_term: f64,
    pub joint_term: f64,
    /// Per body: the summed squared world and joint angles.
    per_body: Vec<(f64, f64)>,
}

impl PoseError {
    pub fn add(&mut self, model: &CharacterModel, sim: &[BodyState], reference: &[BodyState]) {
        self.per_body.resize(model.bodies.len(), (0.0, 0.0));
        let (mut world, mut joint) = (0f64, 0f64);
        for (i, body) in model.bodies.iter().enumerate() {
            let w = f64::from(sim[i].rot.angle_between(reference[i].rot)).powi(2);
            let j = match body.parent {
                Some(p) => {
                    let (a, _) = lhm_sim::obs::joint_state(&sim[p], &sim[i]);
                    let (b, _) = lhm_sim::obs::joint_state(&reference[p], &reference[i]);
                    f64::from(a.angle_between(b)).powi(2)
                }
                None => w,
            };
            world += w;
            joint += j;
            self.per_body[i].0 += w;
            self.per_body[i].1 += j;
        }
        self.steps += 1;
        self.world += world;
        self.joint += joint;
        self.world_term += (-2.0 * world).exp();
        self.joint_term += (-2.0 * joint).exp();
    }

    #[allow(dead_code)] // not every probe prints the per-body table
    pub fn print(&self) {
        let n = self.steps.max(1) as f64;
        println!(
            "imitation pose error over {} walking steps: mean sum of squared angles world {:.3} rad² \
             (pose part exp(-2·sum) {:.4}), per joint {:.3} rad² ({:.4})",
            self.steps,
            self.world / n,
            self.world_term / n,
            self.joint / n,
            self.joint_term / n
        );
        let deg = 180.0 / std::f64::consts::PI;
        let cells: Vec<String> = self
            .per_body
            .iter()
            .enumerate()
            .map(|(i, (w, j))| {
                format!(
                    "{i}: {:.1}°/{:.1}°",
                    (w / n).sqrt() * deg,
                    (j / n).sqrt() * deg
                )
            })
            .collect();
        println!("  rms angle per body, world/joint: {}", cells.join(", "));
    }
}
