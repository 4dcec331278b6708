//! The paper's training stages as presets of one [`TrainConfig`]: the same actor–learner run,
//! differing only in what the actors roll out (role, tasks, the frozen teachers) and what the
//! learner optimises (the reward weights and where the weights start for PPO + AMP; regression
//! onto the teachers' labels for the student and the VLA, `super::optimise`).

use super::{ServiceError, TrainConfig};
use std::path::{Path, PathBuf};

/// Release-and-retreat weight a `t1-rr` stage uses when its configuration leaves the term off.
/// The paper gives no weight; 0.5 (× the task weight) lets a full retreat during the hold pay
/// as much as the place term at the goal.
pub const DEFAULT_RELEASE_RETREAT_WEIGHT: f32 = 0.5;

/// One stage of the pipeline (paper Sec. 3, Algorithm 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Stage {
    /// Teacher 1 pretraining on the single-object tasks (PPO + AMP).
    #[serde(rename = "t1")]
    T1,
    /// Teacher 1 fine-tuned from `t1` with the release-and-retreat reward.
    #[serde(rename = "t1-rr")]
    T1Rr,
    /// Teacher 2 on the second pair of two-object tasks, from Teacher 1's terminal states.
    #[serde(rename = "t2")]
    T2,
    /// The unified student, distilled from both teachers by DAgger on two-object tasks.
    #[serde(rename = "student")]
    Student,
    /// The VLA extension (paper Sec. 3.4): the unified student distilled again by DAgger into a
    /// policy that sees only egocentric RGB, proprioception and each cycle's instruction.
    #[serde(rename = "vla")]
    Vla,
    /// Baseline "End-to-End RL": one policy trained from scratch by PPO (+AMP) on whole
    /// two-object tasks, every cycle in one reset-free episode.
    #[serde(rename = "e2e")]
    E2e,
    /// Baseline "Curriculum RL" (the single-teacher case): the Teacher 1 policy trained further
    /// by PPO (+AMP) on whole two-object tasks, so one policy learns every cycle.
    #[serde(rename = "curriculum")]
    Curriculum,
    /// Baseline "Hierarchical RL": five low-level skills (walk, reach-and-grasp, lift, carry,
    /// place-and-release) switched by a privileged state machine (`[env.skills]`), each paid its
    /// own reward terms and ended when the machine moves on, trained by PPO (+AMP) from scratch
    /// on whole two-object tasks. The skills share one network that reads the machine's choice
    /// as a one-hot (ASE/TokenHSI-style skill conditioning) instead of five separate networks.
    #[serde(rename = "hierarchical")]
    Hierarchical,
}

/// DAgger rows a `vla` stage keeps unless its configuration sets `dagger.capacity`.
pub const VLA_DAGGER_CAPACITY: usize = 20_000;

/// The words of every training instruction (the VLA's vocabulary): the unseen split's new
/// sentence frames are left for the encoder to meet as unknown words.
pub fn training_vocabulary(scenes: Option<&Path>) -> Result<Vec<String>, ServiceError> {
    let bench = match scenes {
        Some(dir) => lhm_scenes::Benchmark::load_dir(dir),
        None => lhm_scenes::Benchmark::embedded(),
    }
    .map_err(|e| ServiceError::Config(format!("the VLA's vocabulary needs the scenes: {e}")))?;
    let instructions = |split| {
        bench
            .tasks(split)
            .iter()
            .flat_map(|t: &lhm_scenes::Task| t.sequence.iter().map(|s| s.instruction.clone()))
            .collect::<Vec<String>>()
    };
    let train = instructions(lhm_scenes::Split::Train);
    let vocabulary = lhm_sim::vla::Vocabulary::from_instructions(train.iter().map(String::as_str));
    // What the unseen split's new sentence frames cost the tokenizer.
    let (mut words, mut unknown) = (0usize, 0usize);
    for text in instructions(lhm_scenes::Split::Unseen) {
        for word in lhm_sim::vla::words(&text) {
            words += 1;
            unknown += usize::from(vocabulary.id(&word) == lhm_sim::vla::UNKNOWN);
        }
    }
    tracing::info!(
        "VLA vocabulary: {} words from {} training instructions; {unknown} of the unseen \
         instructions' {words} words ({:.1} %) are unknown to it",
        vocabulary.words.len(),
        train.len(),
        100.0 * unknown as f64 / words.max(1) as f64
    );
    Ok(vocabulary.words)
}

impl Stage {
    pub const ALL: [Stage; 8] = [
        Stage::T1,
        Stage::T1Rr,
        Stage::T2,
        Stage::Student,
        Stage::Vla,
        Stage::E2e,
        Stage::Curriculum,
        Stage::Hierarchical,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::T1 => "t1",
            Stage::T1Rr => "t1-rr",
            Stage::T2 => "t2",
            Stage::Student => "student",
            Stage::Vla => "vla",
            Stage::E2e => "e2e",
            Stage::Curriculum => "curriculum",
            Stage::Hierarchical => "hierarchical",
        }
    }

    /// `t1`, `t1-rr`, `t2`, `student`, `vla`, or the baselines' `e2e`, `curriculum` and
    /// `hierarchical`.
    pub fn parse(text: &str) -> Result<Self, ServiceError> {
        Self::ALL
            .into_iter()
            .find(|s| s.name() == text)
            .ok_or_else(|| {
                ServiceError::Config(format!(
                    "stage {text:?} is not one of t1, t1-rr, t2, student, vla, e2e, curriculum, \
                     hierarchical"
                ))
            })
    }

    /// Applies the stage to `config`. `teacher1` is the Teacher 1 policy a later stage starts
    /// from (`t1-rr`: its weights; `t2`: the frozen policy that plays each episode's first pair,
    /// and T2's starting weights; `student`: the first cycle's labeller) and `teacher2` Teacher
    /// 2's (`student`: the later cycles' labeller): checkpoint stems such as `runs/p/t1/policy`.
    ///
    /// - `t1`: role teacher1, as configured (a `teacher1` is refused: t1 starts from scratch).
    /// - `t1-rr`: role teacher1, initialised from the configuration's `init_from` if it has one,
    ///   else from `teacher1`; release-and-retreat weight [`DEFAULT_RELEASE_RETREAT_WEIGHT`]
    ///   unless the configuration sets a positive one (0 reads as unset: a t1-rr without the term
    ///   is a t1 run with `init_from`).
    /// - `t2`: role teacher2 with `teacher1` frozen for the first pair, initialised from it,
    ///   on the two-object training tasks unless the configuration lists others.
    /// - `student`: role student, both teachers frozen as labellers (the given ones win over the
    ///   configuration's), no AMP (it learns by regression), on the two-object training tasks
    ///   unless the configuration lists others; its weights start fresh.
    /// - `vla`: role vla, the unified student (`teacher1` here) frozen as the labeller of every
    ///   cycle (the configuration's `teacher1` if none is given), no AMP, on the two-object
    ///   training tasks unless the configuration lists others; the policy gets the VLA encoder
    ///   (the configuration's `[network.policy.vla]` sizes, or the defaults) with the character's
    ///   proprioception width and, unless the configuration lists one, the vocabulary of the
    ///   training instructions.
    /// - `e2e`: role teacher1 from scratch (a `teacher1` is refused) on the two-object training
    ///   tasks, whole episodes, unless the configuration lists other tasks.
    /// - `curriculum`: role teacher1 initialised like `t1-rr` (the configuration's `init_from`,
    ///   else `teacher1`), on the two-object training tasks unless the configuration lists others.
    /// - `hierarchical`: `e2e` with the skill machine on (the configuration's `[env.skills]`, or
    ///   the defaults) and, unless the configuration sets a positive one, release-and-retreat
    ///   weight [`DEFAULT_RELEASE_RETREAT_WEIGHT`] (place-and-release is paid for letting go).
    pub fn apply(
        self,
        config: &mut TrainConfig,
        teacher1: Option<&Path>,
        teacher2: Option<&Path>,
    ) -> Result<(), ServiceError> {
        let need = |what: &str| {
            teacher1.map(Path::to_path_buf).ok_or_else(|| {
                ServiceError::Config(format!(
                    "stage {} needs {what} (a Teacher 1 checkpoint, e.g. runs/p/t1/policy)",
                    self.name()
                ))
            })
        };
        if teacher2.is_some() && self != Stage::Student {
            return Err(ServiceError::Config(format!(
                "stage {} takes no Teacher 2 (only the student is distilled from one)",
                self.name()
            )));
        }
        // Only the VLA has an image encoder: a VLA section laid over every stage (a pipeline's
        // --overlay) leaves the others state-based.
        if self != Stage::Vla {
            config.network.policy.vla = None;
        }
        let whole_tasks = |config: &mut TrainConfig| {
            if config.tasks == lhm_cluster::TaskSet::TrainSingleObject {
                config.tasks = lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train);
            }
        };
        match self {
            Stage::E2e | Stage::Hierarchical => {
                if let Some(t) = teacher1 {
                    return Err(ServiceError::Config(format!(
                        "stage {} trains from scratch; it takes no Teacher 1 ({})",
                        self.name(),
                        t.display()
                    )));
                }
                config.role = "teacher1".into();
                whole_tasks(config);
                if self == Stage::Hierarchical {
                    config.env.skills.get_or_insert_with(Default::default);
                    if config.env.weights.release_retreat == 0.0 {
                        config.env.weights.release_retreat = DEFAULT_RELEASE_RETREAT_WEIGHT;
                    }
                }
            }
            Stage::Curriculum => {
                let from: PathBuf = match (&config.init_from, teacher1) {
                    (Some(i), _) => i.clone(),
                    (None, Some(t)) => t.to_path_buf(),
                    (None, None) => need("--init-from")?,
                };
                config.role = "teacher1".into();
                config.init_from = Some(from);
                whole_tasks(config);
            }
            Stage::T1 => {
                if let Some(t) = teacher1 {
                    return Err(ServiceError::Config(format!(
                        "stage t1 trains from scratch; a Teacher 1 ({}) is for t1-rr (--init-from) \
                         and t2 (--teacher1)",
                        t.display()
                    )));
                }
                config.role = "teacher1".into();
            }
            Stage::T1Rr => {
                // An explicit init_from (the stage's configuration, --init-from) wins.
                let from: PathBuf = match (&config.init_from, teacher1) {
                    (Some(i), _) => i.clone(),
                    (None, Some(t)) => t.to_path_buf(),
                    (None, None) => need("--init-from")?,
                };
                config.role = "teacher1".into();
                config.init_from = Some(from);
                if config.env.weights.release_retreat == 0.0 {
                    config.env.weights.release_retreat = DEFAULT_RELEASE_RETREAT_WEIGHT;
                }
            }
            Stage::T2 => {
                let t1 = match (&config.teacher1, teacher1) {
                    (_, Some(t)) => t.to_path_buf(),
                    (Some(t), None) => t.clone(),
                    (None, None) => need("--teacher1")?,
                };
                config.role = "teacher2".into();
                if config.init_from.is_none() {
                    config.init_from = Some(t1.clone());
                }
                config.teacher1 = Some(t1);
                whole_tasks(config);
            }
            Stage::Vla => {
                let labeller = teacher1
                    .map(Path::to_path_buf)
                    .or_else(|| config.teacher1.clone())
                    .ok_or_else(|| {
                        ServiceError::Config(
                            "stage vla needs the unified student to label with: --teacher1 \
                             runs/p/student/policy"
                                .into(),
                        )
                    })?;
                let mut vla = config.network.policy.vla.clone().unwrap_or_default();
                vla.proprio_dim =
                    lhm_sim::obs::proprioception_dim(&lhm_sim::CharacterModel::amp_humanoid());
                if vla.vocabulary.is_empty() {
                    vla.vocabulary = training_vocabulary(config.scenes.as_deref())?;
                }
                // Its labeller stands on both teachers' keys: one policy for every cycle.
                config.teacher1 = Some(labeller.clone());
                config.teacher2 = Some(labeller);
                config.network.policy.vla = Some(vla);
                // A VLA row carries an image (~50 KB at 64 × 64): the student's default of 100k
                // rows would be 5 GB; a configured capacity is kept.
                if config.dagger.capacity == crate::dagger::DaggerConfig::default().capacity {
                    config.dagger.capacity = VLA_DAGGER_CAPACITY;
                }
                config.role = "vla".into();
                config.amp_enabled = false;
                whole_tasks(config);
            }
            Stage::Student => {
                let pick = |given: Option<&Path>, configured: &Option<PathBuf>, what: &str| {
                    given
                        .map(Path::to_path_buf)
                        .or_else(|| configured.clone())
                        .ok_or_else(|| {
                            ServiceError::Config(format!(
                                "stage student needs --{what} (a {what} checkpoint, e.g. \
                                 runs/p/{}/policy)",
                                if what == "teacher1" { "t1-rr" } else { "t2" }
                            ))
                        })
                };
                // Both checked before either is set: a refused stage leaves the config as it was.
                let t1 = pick(teacher1, &config.teacher1, "teacher1")?;
                let t2 = pick(teacher2, &config.teacher2, "teacher2")?;
                config.teacher1 = Some(t1);
                config.teacher2 = Some(t2);
                config.role = "student".into();
                config.amp_enabled = false;
                whole_tasks(config);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vla_stage_labels_with_the_student_and_only_it_keeps_an_image_encoder() {
        let mut vla = TrainConfig::default();
        assert!(
            Stage::Vla.apply(&mut vla, None, None).is_err(),
            "needs a student"
        );
        let student = Path::new("runs/p/student/policy");
        Stage::Vla.apply(&mut vla, Some(student), None).unwrap();
        assert_eq!(vla.role, "vla");
        assert!(!vla.amp_enabled);
        assert_eq!(vla.teacher1.as_deref(), Some(student));
        assert_eq!(vla.teacher2.as_deref(), Some(student));
        assert_eq!(vla.dagger.capacity, VLA_DAGGER_CAPACITY);
        let encoder = vla.network.policy.vla.clone().expect("the VLA encoder");
        assert_eq!(encoder.proprio_dim, 226);
        assert!(encoder.vocabulary.len() > 50, "{:?}", encoder.vocabulary);
        assert!(encoder.vocabulary.iter().any(|w| w == "put"));
        assert_eq!(vla.run_spec().obs_dim, encoder.obs_dim());
        vla.check().unwrap();
        // A VLA section laid over every stage stays with the vla stage only.
        let mut t1 = TrainConfig::default();
        t1.network.policy.vla = Some(encoder);
        let mut refused = t1.clone();
        refused.role = "teacher1".into();
        let e = refused.check().unwrap_err().to_string();
        assert!(e.contains("network.policy.vla"), "{e}");
        Stage::T1.apply(&mut t1, None, None).unwrap();
        assert!(t1.network.policy.vla.is_none());
        t1.check().unwrap();
    }

    #[test]
    fn each_stage_sets_its_role_start_and_reward() {
        let mut t1 = TrainConfig::default();
        assert!(Stage::T1
            .apply(&mut t1, Some(Path::new("x/policy")), None)
            .is_err());
        Stage::T1.apply(&mut t1, None, None).unwrap();
        assert_eq!(t1.role, "teacher1");
        assert_eq!(t1.env.weights.release_retreat, 0.0);

        let mut rr = TrainConfig::default();
        assert!(
            Stage::T1Rr.apply(&mut rr, None, None).is_err(),
            "t1-rr needs a Teacher 1"
        );
        Stage::T1Rr
            .apply(&mut rr, Some(Path::new("runs/p/t1/policy")), None)
            .unwrap();
        assert_eq!(rr.init_from.as_deref(), Some(Path::new("runs/p/t1/policy")));
        assert_eq!(
            rr.env.weights.release_retreat,
            DEFAULT_RELEASE_RETREAT_WEIGHT
        );
        // A weight the configuration sets is kept.
        let mut rr2 = TrainConfig::default();
        rr2.env.weights.release_retreat = 2.0;
        Stage::T1Rr
            .apply(&mut rr2, Some(Path::new("a/policy")), None)
            .unwrap();
        assert_eq!(rr2.env.weights.release_retreat, 2.0);
        // An explicit init_from wins over the previous stage's policy.
        let mut rr3 = TrainConfig {
            init_from: Some(PathBuf::from("mine/policy")),
            ..TrainConfig::default()
        };
        Stage::T1Rr
            .apply(&mut rr3, Some(Path::new("runs/p/t1/policy")), None)
            .unwrap();
        assert_eq!(rr3.init_from.as_deref(), Some(Path::new("mine/policy")));

        let mut t2 = TrainConfig::default();
        assert!(
            Stage::T2.apply(&mut t2, None, None).is_err(),
            "t2 needs a Teacher 1"
        );
        Stage::T2
            .apply(&mut t2, Some(Path::new("runs/p/t1-rr/policy")), None)
            .unwrap();
        assert_eq!(t2.role, "teacher2");
        assert_eq!(
            t2.teacher1.as_deref(),
            Some(Path::new("runs/p/t1-rr/policy"))
        );
        assert_eq!(
            t2.init_from.as_deref(),
            Some(Path::new("runs/p/t1-rr/policy"))
        );
        assert_eq!(
            t2.tasks,
            lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train)
        );
    }

    #[test]
    fn the_baselines_train_one_policy_on_whole_tasks() {
        let mut e2e = TrainConfig::default();
        assert!(Stage::E2e
            .apply(&mut e2e, Some(Path::new("runs/p/t1/policy")), None)
            .is_err());
        Stage::E2e.apply(&mut e2e, None, None).unwrap();
        assert_eq!(e2e.role, "teacher1");
        assert_eq!(e2e.init_from, None);
        assert_eq!(
            e2e.tasks,
            lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train)
        );
        let mut c = TrainConfig::default();
        assert!(Stage::Curriculum.apply(&mut c, None, None).is_err());
        Stage::Curriculum
            .apply(&mut c, Some(Path::new("runs/p/t1/policy")), None)
            .unwrap();
        assert_eq!(c.init_from.as_deref(), Some(Path::new("runs/p/t1/policy")));
        assert_eq!(c.env.weights.release_retreat, 0.0);
        assert_eq!(
            c.tasks,
            lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train)
        );
        // Hierarchical RL: e2e with the skill machine, its one-hot in the policy's input, and
        // place-and-release paid for letting go; a configured machine and weight are kept.
        let mut h = TrainConfig::default();
        assert!(Stage::Hierarchical
            .apply(&mut h, Some(Path::new("runs/p/t1/policy")), None)
            .is_err());
        Stage::Hierarchical.apply(&mut h, None, None).unwrap();
        assert_eq!(
            (h.role.as_str(), h.init_from.as_deref()),
            ("teacher1", None)
        );
        assert_eq!(h.env.skills, Some(Default::default()));
        assert_eq!(
            h.env.weights.release_retreat,
            DEFAULT_RELEASE_RETREAT_WEIGHT
        );
        assert_eq!(
            h.run_spec().obs_dim,
            TrainConfig::default().run_spec().obs_dim + 5
        );
        h.check().unwrap();
        let mut tuned = TrainConfig::default();
        tuned.env.skills = Some(lhm_sim::task::skills::SkillConfig {
            grasp_distance: 0.05,
            ..Default::default()
        });
        tuned.env.weights.release_retreat = 0.2;
        Stage::Hierarchical.apply(&mut tuned, None, None).unwrap();
        assert_eq!(tuned.env.skills.map(|s| s.grasp_distance), Some(0.05));
        assert_eq!(tuned.env.weights.release_retreat, 0.2);
    }

    #[test]
    fn stage_names_round_trip_and_an_unknown_one_is_refused_by_name() {
        for s in Stage::ALL {
            assert_eq!(Stage::parse(s.name()).unwrap(), s);
        }
        let e = Stage::parse("t3").unwrap_err().to_string();
        assert!(e.contains("\"t3\"") && e.contains("student"), "{e}");
    }

    #[test]
    fn the_student_needs_both_teachers_and_learns_without_amp() {
        let (t1, t2) = (
            Path::new("runs/p/t1-rr/policy"),
            Path::new("runs/p/t2/policy"),
        );
        let mut s = TrainConfig::default();
        let e = Stage::Student.apply(&mut s, Some(t1), None).unwrap_err();
        assert!(e.to_string().contains("--teacher2"), "{e}");
        let e = Stage::Student.apply(&mut s, None, Some(t2)).unwrap_err();
        assert!(e.to_string().contains("--teacher1"), "{e}");
        Stage::Student.apply(&mut s, Some(t1), Some(t2)).unwrap();
        assert_eq!(s.role, "student");
        assert!(!s.amp_enabled);
        assert_eq!(s.teacher1.as_deref(), Some(t1));
        assert_eq!(s.teacher2.as_deref(), Some(t2));
        assert_eq!(
            s.tasks,
            lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train)
        );
        s.check().unwrap();
        // Only the student takes a Teacher 2.
        let e = Stage::T2
            .apply(&mut TrainConfig::default(), Some(t1), Some(t2))
            .unwrap_err();
        assert!(e.to_string().contains("no Teacher 2"), "{e}");
    }
}
