//! The CPU renderer draws what the cameras look at.

use lhm_scenes::{Benchmark, Split};
use lhm_sim::render::{render, write_gif, Camera};
use lhm_sim::{CharacterModel, SimConfig, World};

fn pixel(img: &lhm_sim::render::Image, x: u32, y: u32) -> [u8; 3] {
    let i = ((y * img.width + x) * 3) as usize;
    [img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]]
}

fn is_character_blue(p: [u8; 3]) -> bool {
    u16::from(p[2]) > u16::from(p[0]) + 40 && p[2] > p[1]
}

#[test]
fn third_person_sees_the_character_and_ego_does_not_see_its_own_head() {
    let b = Benchmark::embedded().expect("benchmark");
    let model = CharacterModel::amp_humanoid();
    let w = World::with_task(
        &model,
        SimConfig::default(),
        &b.tasks(Split::Train)[1],
        &b.catalogue,
    );
    let cam = Camera::third_person(&w, 64, 48);
    let img = render(&w, &cam, true);
    assert_eq!(img.rgb.len(), 64 * 48 * 3);
    assert!(
        is_character_blue(pixel(&img, 32, 24)),
        "the pelvis is at the image centre: {:?}",
        pixel(&img, 32, 24)
    );
    // The top row is sky (or far floor), never the character.
    assert!(!is_character_blue(pixel(&img, 32, 0)));
    let ego = render(&w, &Camera::egocentric(&w, 64, 48), false);
    let blue = (0..48)
        .flat_map(|y| (0..64).map(move |x| (x, y)))
        .filter(|&(x, y)| is_character_blue(pixel(&ego, x, y)))
        .count();
    assert!(
        blue < 64 * 48 / 4,
        "the egocentric view is not filled by the character's own head ({blue} px)"
    );
    let mut gif = Vec::new();
    write_gif(&[img, ego], 7, &mut gif).expect("gif");
    assert_eq!(&gif[..6], b"GIF89a");
}
