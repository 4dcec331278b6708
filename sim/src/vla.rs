//! What the VLA student sees (paper Sec. 3.4): the character's first-person RGB image, its
//! proprioception and the current cycle's instruction as word tokens. Nothing privileged about
//! the object, the goal or the obstacles: where they are must be read from the image, which of
//! several similar objects to carry from the words.
//!
//! One flat row per step, so the VLA's chunks, DAgger dataset and checkpoints are the same
//! machinery as every other policy's: `[proprioception | tokens | image]`, tokens as word ids
//! (exact in f32), the image as `size × size` pixels row-major, RGB interleaved, in [0, 1].

use serde::{Deserialize, Serialize};

use crate::env::TaskEnv;
use crate::obs::{proprioception, proprioception_dim};
use crate::render::{render, Camera};
use crate::CharacterModel;

/// Word id of padding (after the instruction's last word, and every id of a blanked one).
pub const PAD: u32 = 0;
/// Word id of a word the vocabulary does not hold (e.g. an unseen task's new verb).
pub const UNKNOWN: u32 = 1;

/// The shape of a VLA observation row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VlaLayout {
    /// Proprioception values at the start of the row.
    pub proprio_dim: usize,
    /// Word ids per instruction (longer ones are cut, shorter ones padded with [`PAD`]).
    pub max_tokens: usize,
    /// The square image's side in pixels.
    pub image_size: usize,
}

impl VlaLayout {
    pub fn new(model: &CharacterModel, max_tokens: usize, image_size: usize) -> Self {
        Self {
            proprio_dim: proprioception_dim(model),
            max_tokens,
            image_size,
        }
    }

    pub fn image_len(&self) -> usize {
        3 * self.image_size * self.image_size
    }

    /// Width of one observation row.
    pub fn dim(&self) -> usize {
        self.proprio_dim + self.max_tokens + self.image_len()
    }

    /// Offset of the first token.
    pub fn tokens_at(&self) -> usize {
        self.proprio_dim
    }

    /// Offset of the first image value.
    pub fn image_at(&self) -> usize {
        self.proprio_dim + self.max_tokens
    }
}

/// The words the instruction encoder knows, built from the training instructions only, so the
/// unseen split's new sentence frames meet [`UNKNOWN`] as they would in the paper's setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vocabulary {
    /// Sorted known words; word `words[i]` has id `i + 2` (0 and 1 are [`PAD`] and [`UNKNOWN`]).
    pub words: Vec<String>,
}

/// Lower-case words of a sentence: letters, digits and apostrophes; everything else separates.
pub fn words(text: &str) -> impl Iterator<Item = String> + '_ {
    text.split(|c: char| !(c.is_alphanumeric() || c == '\''))
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
}

impl Vocabulary {
    /// Every word of `instructions`, sorted (so the same instructions give the same ids in every
    /// process).
    pub fn from_instructions<'a>(instructions: impl IntoIterator<Item = &'a str>) -> Self {
        let mut set = std::collections::BTreeSet::new();
        for text in instructions {
            set.extend(words(text));
        }
        Self {
            words: set.into_iter().collect(),
        }
    }

    /// Ids of PAD, UNKNOWN and every word.
    pub fn size(&self) -> usize {
        self.words.len() + 2
    }

    pub fn id(&self, word: &str) -> u32 {
        match self.words.binary_search_by(|w| w.as_str().cmp(word)) {
            Ok(i) => i as u32 + 2,
            Err(_) => UNKNOWN,
        }
    }

    /// `max_tokens` ids for `text`: its words, cut or padded.
    pub fn encode(&self, text: &str, max_tokens: usize) -> Vec<u32> {
        let mut ids: Vec<u32> = words(text).take(max_tokens).map(|w| self.id(&w)).collect();
        ids.resize(max_tokens, PAD);
        ids
    }

    /// Whether the vocabulary's ids are sorted and unique (a vocabulary read from a file).
    pub fn is_well_formed(&self) -> bool {
        self.words.windows(2).all(|w| w[0] < w[1])
    }
}

/// What the VLA sees and whether it hears the instruction.
#[derive(Debug, Clone, PartialEq)]
pub struct VlaView {
    pub layout: VlaLayout,
    pub vocabulary: Vocabulary,
    /// `false`: the instruction is blanked (every token [`PAD`]) — the no-language ablation.
    pub language: bool,
}

impl VlaView {
    /// The instruction of the cycle the character is in (after the last one: the last one, as the
    /// state observation keeps the last pair in view).
    pub fn instruction<'a>(&self, env: &'a TaskEnv) -> &'a str {
        let last = env.task.sequence.len().saturating_sub(1);
        env.task
            .sequence
            .get(env.cycles.current.min(last))
            .map_or("", |s| s.instruction.as_str())
    }

    /// The row for `env`'s current state.
    pub fn observation(&self, env: &TaskEnv) -> Vec<f32> {
        let layout = &self.layout;
        let mut row = Vec::with_capacity(layout.dim());
        row.extend(proprioception(&env.world.body_states()));
        if self.language {
            let ids = self
                .vocabulary
                .encode(self.instruction(env), layout.max_tokens);
            row.extend(ids.into_iter().map(|id| id as f32));
        } else {
            row.extend(std::iter::repeat_n(PAD as f32, layout.max_tokens));
        }
        row.extend(egocentric_image(env, layout.image_size));
        row
    }
}

/// The head camera's image in [0, 1]: `size × size` pixels row-major, RGB interleaved (the
/// renderer's own layout).
pub fn egocentric_image(env: &TaskEnv, size: usize) -> Vec<f32> {
    let camera = Camera::egocentric(&env.world, size as u32, size as u32);
    let image = render(&env.world, &camera, false);
    image.rgb.iter().map(|&v| f32::from(v) / 255.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_outside_the_vocabulary_are_unknown_and_short_instructions_are_padded() {
        let v = Vocabulary::from_instructions(["Put the laptop on the desk", "move the pot"]);
        assert_eq!(
            v.words,
            ["desk", "laptop", "move", "on", "pot", "put", "the"]
        );
        assert_eq!(v.size(), 9);
        let ids = v.encode("Relocate the laptop, by the window", 8);
        assert_eq!(
            ids,
            [
                UNKNOWN,
                v.id("the"),
                v.id("laptop"),
                UNKNOWN,
                v.id("the"),
                UNKNOWN,
                PAD,
                PAD
            ]
        );
        assert_eq!(v.encode("put the pot on the desk", 3).len(), 3);
        assert!(v.is_well_formed());
        assert!(ids.iter().all(|&id| (id as usize) < v.size()));
    }

    #[test]
    fn ids_are_the_same_whatever_order_the_instructions_come_in() {
        let a = Vocabulary::from_instructions(["b a", "c"]);
        let b = Vocabulary::from_instructions(["c", "a b"]);
        assert_eq!(a, b);
    }
}
