//! The VLA's observation row holds the proprioception, the current cycle's instruction and the
//! head camera's image — and nothing privileged: moving a goal (which is never drawn) leaves the
//! row unchanged while the state observation sees it.

use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::obs::proprioception;
use lhm_sim::room::object_colour;
use lhm_sim::vla::{egocentric_image, VlaLayout, VlaView, Vocabulary, PAD};
use lhm_sim::{CharacterModel, SimConfig};

fn view(model: &CharacterModel, bench: &Benchmark, language: bool) -> VlaView {
    VlaView {
        layout: VlaLayout::new(model, 16, 32),
        vocabulary: Vocabulary::from_instructions(
            bench
                .tasks(Split::Train)
                .iter()
                .flat_map(|t| t.sequence.iter().map(|s| s.instruction.as_str())),
        ),
        language,
    }
}

fn env(model: &CharacterModel, bench: &Benchmark, task: &Task) -> TaskEnv {
    TaskEnv::new(
        model,
        task,
        &bench.catalogue,
        SimConfig::default(),
        EnvConfig::default(),
    )
}

#[test]
fn a_vla_row_is_proprioception_the_current_instruction_and_the_head_camera() {
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let task = &bench.tasks(Split::Train)[0];
    assert!(task.sequence.len() >= 2);
    let v = view(&model, &bench, true);
    let mut e = env(&model, &bench, task);
    let row = v.observation(&e);
    let l = &v.layout;
    assert_eq!(row.len(), l.dim());
    assert_eq!(
        &row[..l.proprio_dim],
        &proprioception(&e.world.body_states())[..]
    );
    let tokens = |row: &[f32]| -> Vec<u32> {
        row[l.tokens_at()..l.image_at()]
            .iter()
            .map(|&x| x as u32)
            .collect()
    };
    let first = v.vocabulary.encode(&task.sequence[0].instruction, 16);
    assert_eq!(tokens(&row), first);
    assert!(first.iter().filter(|&&id| id != PAD).count() >= 3);
    assert_eq!(&row[l.image_at()..], &egocentric_image(&e, 32)[..]);
    assert!(row[l.image_at()..]
        .iter()
        .all(|&p| (0.0..=1.0).contains(&p)));
    // The next cycle hears the next instruction.
    e.cycles.current = 1;
    let second = v.vocabulary.encode(&task.sequence[1].instruction, 16);
    assert_ne!(first, second);
    assert_eq!(tokens(&v.observation(&e)), second);
    // Without language every token is padding; the rest of the row is unchanged.
    let deaf = view(&model, &bench, false).observation(&e);
    assert!(tokens(&deaf).iter().all(|&id| id == PAD));
    assert_eq!(&deaf[l.image_at()..], &v.observation(&e)[l.image_at()..]);
}

#[test]
fn no_privileged_goal_state_reaches_the_vla_row() {
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let task = bench.tasks(Split::Train)[3].clone();
    let mut moved = task.clone();
    for step in &mut moved.sequence {
        step.goal[0] += 0.7;
        step.goal[1] -= 0.4;
    }
    let (a, b) = (env(&model, &bench, &task), env(&model, &bench, &moved));
    assert_ne!(
        a.observation(),
        b.observation(),
        "the state observation sees the goal"
    );
    let v = view(&model, &bench, true);
    assert_eq!(v.observation(&a), v.observation(&b));
}

#[test]
fn objects_of_one_category_look_alike_and_categories_differ() {
    let bench = Benchmark::embedded().unwrap();
    let c = &bench.catalogue;
    let d = |a: &str, b: &str| {
        let (x, y) = (object_colour(c, a), object_colour(c, b));
        (0..3).map(|i| (x[i] - y[i]).abs()).fold(0.0, f32::max)
    };
    assert!(d("pot", "kettle") < 0.08, "{}", d("pot", "kettle"));
    assert!(d("pot", "kettle") > 0.0);
    assert!(d("pot", "laptop") > 0.3, "{}", d("pot", "laptop"));
    assert!(d("storage_box", "toolbox") > 0.3);
}
