//! The committed benchmark: counts of the paper, validity, determinism, unseen/train separation.

use lhm_scenes::generate::{generate, to_toml, GenerateConfig};
use lhm_scenes::routes::Clearance;
use lhm_scenes::validate::{layout_signature, object_choice, validate_benchmark};
use lhm_scenes::{stats, Benchmark, RoomType, Split};
use std::collections::{BTreeMap, HashSet};

fn bench() -> Benchmark {
    Benchmark::embedded().expect("committed benchmark loads")
}

#[test]
fn counts_match_the_paper() {
    let b = bench();
    assert_eq!(b.catalogue.objects.len(), 79);
    assert_eq!(b.catalogue.movable().count(), 25);
    assert_eq!(b.tasks(Split::Train).len(), 350);
    assert_eq!(b.tasks(Split::Unseen).len(), 66);
    for split in [Split::Train, Split::Unseen] {
        assert!(b
            .tasks(split)
            .iter()
            .all(|t| t.sequence.len() == 2 && t.objects.len() == 2));
    }
    let mut ext: BTreeMap<usize, HashSet<RoomType>> = BTreeMap::new();
    let mut ext_counts: BTreeMap<usize, usize> = BTreeMap::new();
    for t in b.tasks(Split::Extension) {
        ext.entry(t.sequence.len()).or_default().insert(t.room);
        *ext_counts.entry(t.sequence.len()).or_default() += 1;
    }
    assert_eq!(ext.keys().copied().collect::<Vec<_>>(), vec![3, 4, 5]);
    for (n, rooms) in &ext {
        assert_eq!(rooms.len(), 4, "{n}-object tasks cover all room types");
        assert!(ext_counts[n] >= 20, "{n}-object tasks: {}", ext_counts[n]);
    }
    for (_, t) in b.all_tasks() {
        assert!(
            (4..=10).contains(&t.obstacles.len()),
            "{}: {} obstacles",
            t.id,
            t.obstacles.len()
        );
    }
    let rooms: HashSet<RoomType> = b.tasks(Split::Train).iter().map(|t| t.room).collect();
    assert_eq!(rooms.len(), 4);
}

#[test]
fn every_split_validates() {
    let problems = validate_benchmark(&bench(), None, &Clearance::default());
    assert!(
        problems.is_empty(),
        "{} problems, first: {}",
        problems.len(),
        problems[0]
    );
}

#[test]
fn generation_reproduces_the_committed_files() {
    let b = bench();
    let files =
        generate(&b.catalogue, &GenerateConfig::default(), |_, _, _| {}).expect("generates");
    let committed = [
        include_str!("../data/train.toml"),
        include_str!("../data/unseen.toml"),
        include_str!("../data/extension.toml"),
    ];
    for (file, text) in files.iter().zip(committed) {
        let fresh = to_toml(file).expect("serialises");
        assert!(
            fresh == text,
            "{} differs from a fresh generation: run `lhm scenes generate`",
            file.split
        );
    }
}

#[test]
fn unseen_is_separated_from_train() {
    let b = bench();
    let train = b.tasks(Split::Train);
    let layouts: HashSet<_> = train.iter().map(layout_signature).collect();
    let choices: HashSet<_> = train.iter().map(object_choice).collect();
    let instructions: HashSet<&str> = train
        .iter()
        .flat_map(|t| t.sequence.iter().map(|s| s.instruction.as_str()))
        .collect();
    for t in train {
        assert_eq!(t.centroid, [0.0, 0.0]);
    }
    let mut max_shift: f64 = 0.0;
    for t in b.tasks(Split::Unseen) {
        assert!(!layouts.contains(&layout_signature(t)), "{}", t.id);
        assert!(!choices.contains(&object_choice(t)), "{}", t.id);
        for s in &t.sequence {
            assert!(
                !instructions.contains(s.instruction.as_str()),
                "{}: {}",
                t.id,
                s.instruction
            );
        }
        let shift = t.centroid[0].hypot(t.centroid[1]);
        assert!(shift > 0.0 && shift <= 0.5, "{}: shift {shift}", t.id);
        max_shift = max_shift.max(shift);
    }
    assert!(max_shift > 0.4, "shifts reach ~0.5 m, max {max_shift}");
}

#[test]
fn stats_json_has_the_documented_keys() {
    let s = serde_json::to_value(stats::compute(&bench())).expect("json");
    assert_eq!(s.pointer("/splits/train/tasks"), Some(&350.into()));
    assert_eq!(s.pointer("/splits/unseen/tasks"), Some(&66.into()));
    assert_eq!(s.pointer("/room_types"), Some(&4.into()));
    assert_eq!(s.pointer("/object_types"), Some(&79.into()));
    assert_eq!(s.pointer("/movable_object_types"), Some(&25.into()));
    let by_objects = s
        .pointer("/splits/extension/tasks_by_objects")
        .and_then(|v| v.as_object())
        .expect("map");
    assert_eq!(
        by_objects.keys().cloned().collect::<Vec<_>>(),
        vec!["3", "4", "5"]
    );
    let min = s
        .pointer("/obstacles_per_scene/min")
        .and_then(|v| v.as_f64())
        .expect("min");
    let max = s
        .pointer("/obstacles_per_scene/max")
        .and_then(|v| v.as_f64())
        .expect("max");
    assert!(min >= 4.0 && max <= 10.0 && min < max);
    assert_eq!(
        s.pointer("/instructions/unseen_instructions_in_train"),
        Some(&0.into())
    );
}

#[test]
fn training_tasks_split_into_700_single_object_tasks() {
    let b = Benchmark::embedded().unwrap();
    let singles = b.single_object_tasks(Split::Train);
    assert_eq!(singles.len(), 700);
    let parent = &b.tasks(Split::Train)[0];
    let second = &singles[1];
    assert_eq!(second.id, format!("{}.p2", parent.id));
    assert_eq!(second.sequence, vec![parent.sequence[1].clone()]);
    // The room and every object stay: the other object is clutter now.
    assert_eq!(second.objects, parent.objects);
    assert_eq!(second.obstacles, parent.obstacles);
    // Ids of single-object tasks resolve like any other task id.
    let (split, found) = b.task(&second.id).unwrap();
    assert_eq!(split, Split::Train);
    assert_eq!(&found, second);
    assert!(b.task(&format!("{}.p3", parent.id)).is_none());
    assert!(b.task(&format!("{}.p0", parent.id)).is_none());
}
