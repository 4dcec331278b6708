//! Bad scene files are errors that name the file, the task and the field.

use lhm_scenes::generate::to_toml;
use lhm_scenes::load::parse_split;
use lhm_scenes::{Benchmark, SceneError, Split, SplitFile, Support};

const FILE: &str = "scenes/data/test.toml";

fn one_task_file() -> (Benchmark, SplitFile) {
    let b = Benchmark::embedded().expect("loads");
    let mut f = b.splits[&Split::Train].clone();
    f.tasks.truncate(2);
    (b, f)
}

fn parse_err(b: &Benchmark, text: &str) -> String {
    match parse_split(text, FILE, &b.catalogue) {
        Ok(_) => panic!("accepted a bad file"),
        Err(e) => e.to_string(),
    }
}

fn field_err(b: &Benchmark, f: &SplitFile) -> String {
    parse_err(b, &to_toml(f).expect("serialises"))
}

#[test]
fn valid_file_round_trips() {
    let (b, f) = one_task_file();
    let back = parse_split(&to_toml(&f).expect("ser"), FILE, &b.catalogue).expect("parses");
    assert_eq!(back, f);
}

#[test]
fn syntax_error_names_the_file_and_line() {
    let (b, f) = one_task_file();
    let text = to_toml(&f).expect("ser").replacen("room = ", "room == ", 1);
    let e = parse_err(&b, &text);
    assert!(e.contains(FILE) && e.contains("line"), "{e}");
}

#[test]
fn wrong_type_names_task_and_field_path() {
    let (b, f) = one_task_file();
    let mut v = toml::Value::try_from(&f).expect("to value");
    let task = &mut v["task"][1];
    task["object"][0]["mass"] = toml::Value::String("heavy".into());
    let e = parse_err(&b, &toml::to_string(&v).expect("ser"));
    assert!(
        e.contains(FILE) && e.contains(&f.tasks[1].id) && e.contains("object[0].mass"),
        "{e}"
    );
}

#[test]
fn unknown_field_is_rejected() {
    let (b, f) = one_task_file();
    let mut v = toml::Value::try_from(&f).expect("to value");
    v["task"][0]["obstacle"][0]
        .as_table_mut()
        .expect("table")
        .insert("colour".into(), toml::Value::String("red".into()));
    let e = parse_err(&b, &toml::to_string(&v).expect("ser"));
    assert!(e.contains("obstacle[0]") && e.contains("colour"), "{e}");
}

#[test]
fn inconsistencies_name_the_field() {
    let (b, base) = one_task_file();
    let id = base.tasks[0].id.clone();
    type Mutation = Box<dyn Fn(&mut SplitFile)>;
    let cases: Vec<(&str, Mutation)> = vec![
        (
            "obstacle[0].kind",
            Box::new(|f| f.tasks[0].obstacles[0].kind = "spaceship".into()),
        ),
        (
            "obstacle[0].size",
            Box::new(|f| f.tasks[0].obstacles[0].size[2] += 0.5),
        ),
        (
            "object[1].mass",
            Box::new(|f| f.tasks[0].objects[1].mass *= 2.0),
        ),
        (
            "object[0].on",
            Box::new(|f| f.tasks[0].objects[0].on = Support::Surface("o99".into())),
        ),
        (
            "step[1].object",
            Box::new(|f| f.tasks[0].sequence[1].object = "m7".into()),
        ),
        (
            "step[0].instruction",
            Box::new(|f| f.tasks[0].sequence[0].instruction = " ".into()),
        ),
        (
            "object[1].id",
            Box::new(|f| f.tasks[0].objects[1].id = f.tasks[0].objects[0].id.clone()),
        ),
        ("room_size", Box::new(|f| f.tasks[0].room_size[0] = -1.0)),
    ];
    for (field, mutate) in cases {
        let mut f = base.clone();
        mutate(&mut f);
        let e = field_err(&b, &f);
        assert!(
            e.contains(FILE) && e.contains(&id) && e.contains(field),
            "expected {field}: {e}"
        );
    }
    let mut f = base.clone();
    f.tasks[1].id = id.clone();
    let e = field_err(&b, &f);
    assert!(e.contains("duplicate task id"), "{e}");
    let mut f = base;
    f.schema = 9;
    assert!(field_err(&b, &f).contains("`schema`: version 9"));
}

#[test]
fn a_bad_file_in_a_directory_is_named() {
    let dir = std::env::temp_dir().join(format!("lhm-scenes-malformed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp");
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/data");
    for name in ["catalogue.toml", "train.toml", "unseen.toml"] {
        std::fs::copy(format!("{data}/{name}"), dir.join(name)).expect("copy");
    }
    match Benchmark::load_dir(&dir) {
        Err(SceneError::Io { file, .. }) => assert!(file.ends_with("extension.toml"), "{file}"),
        other => panic!("expected a missing-file error, got {other:?}"),
    }
    let text = std::fs::read_to_string(format!("{data}/extension.toml")).expect("read");
    std::fs::write(
        dir.join("extension.toml"),
        text.replacen("kind = \"", "kind = \"not_a_", 1),
    )
    .expect("write");
    let e = Benchmark::load_dir(&dir).expect_err("bad kind").to_string();
    assert!(
        e.contains("extension.toml") && e.contains("extension-3obj-01") && e.contains("kind"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
