//! The VLA student's encoder (paper Sec. 3.4): a small CNN over the egocentric RGB image, a word
//! embedding and a GRU over the instruction, and the proprioception, concatenated into the input
//! of the policy's MLP. Trained jointly, end to end, by the DAgger regression.
//!
//! An observation row is `[proprioception | word ids | image]` (the layout `lhm-sim`'s `vla`
//! module writes): word ids as exact small integers in f32, the image row-major with interleaved
//! RGB in [0, 1]. Only the proprioception goes through the observation normaliser; ids and pixels
//! arrive raw.
//!
//! The CNN's layers are 2×2, stride-2 convolutions (patch merging, as in the patchify stems of
//! ConvNeXt and Swin): each is a reshape of the image into its 2×2 patches and one matrix product,
//! so forward and backward are matrix products. candle's CPU `conv2d` backward (a direct
//! transposed convolution) made a 4×4 stride-2 stack train at ~60 rows/s on this machine.

use candle_core::{DType, Device, Tensor, Var, D};
use serde::{Deserialize, Serialize};

use crate::{Linear, NetError, NetResult, SplitMix64};

/// Shapes of the VLA encoder and the observation layout it reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VlaEncoderConfig {
    /// Proprioception values at the start of a row (set from the character by the learner).
    pub proprio_dim: usize,
    /// Word ids per instruction.
    pub max_tokens: usize,
    /// Side of the square image, pixels.
    pub image_size: usize,
    /// Known words, sorted: word `vocabulary[i]` has id `i + 2` (0: padding, 1: unknown). Built
    /// from the training instructions by the learner and kept with the weights, so a checkpoint
    /// tokenises exactly as it was trained.
    pub vocabulary: Vec<String>,
    /// Output channels of each 2×2, stride-2 convolution (each halves the image side).
    pub conv_channels: Vec<usize>,
    /// Width of the image features after the convolutions.
    pub image_features: usize,
    /// Width of a word embedding.
    pub word_dim: usize,
    /// Width of the GRU state: the instruction's features.
    pub text_features: usize,
}

impl Default for VlaEncoderConfig {
    fn default() -> Self {
        Self {
            proprio_dim: 0,
            max_tokens: 16,
            image_size: 64,
            vocabulary: Vec::new(),
            conv_channels: vec![16, 32, 32],
            image_features: 128,
            word_dim: 32,
            text_features: 64,
        }
    }
}

impl VlaEncoderConfig {
    /// Width of an observation row.
    pub fn obs_dim(&self) -> usize {
        self.proprio_dim + self.max_tokens + 3 * self.image_size * self.image_size
    }

    /// Width of the features the policy's MLP reads.
    pub fn feature_dim(&self) -> usize {
        self.proprio_dim + self.text_features + self.image_features
    }

    /// Padding, unknown, and every known word.
    pub fn vocabulary_size(&self) -> usize {
        self.vocabulary.len() + 2
    }

    fn conv_side(&self) -> usize {
        self.conv_channels
            .iter()
            .fold(self.image_size, |side, _| side / 2)
    }

    pub fn check(&self) -> Result<(), String> {
        if self.proprio_dim == 0 || self.max_tokens == 0 {
            return Err("vla: proprio_dim and max_tokens must be positive".into());
        }
        if self.conv_channels.is_empty() || self.conv_channels.contains(&0) {
            return Err("vla.conv_channels: one or more positive channel counts".into());
        }
        let halvings = self.conv_channels.len() as u32;
        if self.image_size == 0 || self.image_size % (1 << halvings) != 0 {
            return Err(format!(
                "vla.image_size {} must be a positive multiple of {} ({} stride-2 convolutions)",
                self.image_size,
                1 << halvings,
                halvings
            ));
        }
        if self.image_features == 0 || self.word_dim == 0 || self.text_features == 0 {
            return Err("vla: image_features, word_dim and text_features must be positive".into());
        }
        if !self.vocabulary.windows(2).all(|w| w[0] < w[1]) {
            return Err("vla.vocabulary must be sorted and without repeats".into());
        }
        Ok(())
    }
}

/// A GRU cell (PyTorch's gate order r, z, n) whose input projection is applied to every step at
/// once.
#[derive(Debug, Clone)]
struct Gru {
    /// x → 3H for (r, z, n).
    input: Linear,
    /// h → 3H for (r, z, n).
    hidden: Linear,
}

/// Seconds of one regression step's gradient on `raw_rows` (normalise, policy mean, MSE against
/// zero actions, backward): what a DAgger minibatch costs before Adam. For `lhm bench vla`.
pub fn regression_step_seconds(ac: &crate::ActorCritic, raw_rows: &[f32]) -> NetResult<f64> {
    let started = std::time::Instant::now();
    let mean = ac.policy.mean(&ac.input_tensor(raw_rows)?)?;
    let grads = mean.sqr()?.mean_all()?.backward()?;
    std::hint::black_box(grads);
    Ok(started.elapsed().as_secs_f64())
}

/// A 2×2, stride-2 convolution over NHWC activations `x` [B, S, S, C] → [B, S/2, S/2, O]: the
/// image cut into its 2×2 patches (a reshape and a permute), then `layer` ([O, 4·C] weights, the
/// patch's taps row-major, channels inner) on every patch.
fn patch_merge(x: &Tensor, layer: &Linear) -> NetResult<Tensor> {
    let (b, side, _, c) = x.dims4()?;
    let half = side / 2;
    let patches = x
        .reshape((b, half, 2, half, 2 * c))?
        .transpose(2, 3)?
        .contiguous()?
        .reshape((b * half * half, 4 * c))?;
    Ok(layer
        .forward(&patches)?
        .reshape((b, half, half, layer.out_dim()))?)
}

#[derive(Debug, Clone)]
pub struct VlaEncoder {
    config: VlaEncoderConfig,
    /// One per 2×2 stride-2 convolution: [out, 4 · in] weights.
    convs: Vec<Linear>,
    image_out: Linear,
    /// [vocabulary, word_dim]
    words: Var,
    gru: Gru,
}

fn sigmoid(x: &Tensor) -> candle_core::Result<Tensor> {
    (x.neg()?.exp()? + 1.0)?.recip()
}

impl VlaEncoder {
    pub fn new(config: &VlaEncoderConfig, rng: &mut SplitMix64, dtype: DType) -> NetResult<Self> {
        config.check().map_err(NetError::Config)?;
        let mut convs = Vec::new();
        let mut channels = 3;
        for &out in &config.conv_channels {
            convs.push(Linear::new(4 * channels, out, 1.0, rng, dtype)?);
            channels = out;
        }
        let side = config.conv_side();
        let image_out = Linear::new(
            channels * side * side,
            config.image_features,
            1.0,
            rng,
            dtype,
        )?;
        // N(0, 1)-like embeddings (PyTorch's nn.Embedding), drawn uniformly with the same variance.
        let bound = 3f64.sqrt();
        let e: Vec<f64> = (0..config.vocabulary_size() * config.word_dim)
            .map(|_| rng.uniform(-bound, bound))
            .collect();
        let words = Var::from_tensor(
            &Tensor::from_vec(e, (config.vocabulary_size(), config.word_dim), &Device::Cpu)?
                .to_dtype(dtype)?,
        )?;
        let h = config.text_features;
        let gru = Gru {
            input: Linear::new(config.word_dim, 3 * h, 1.0, rng, dtype)?,
            hidden: Linear::new(h, 3 * h, 1.0, rng, dtype)?,
        };
        Ok(Self {
            config: config.clone(),
            convs,
            image_out,
            words,
            gru,
        })
    }

    pub fn config(&self) -> &VlaEncoderConfig {
        &self.config
    }

    pub fn obs_dim(&self) -> usize {
        self.config.obs_dim()
    }

    pub fn feature_dim(&self) -> usize {
        self.config.feature_dim()
    }

    /// Image rows [B, S·S·3] (row-major, RGB interleaved) → features [B, image_features].
    fn image(&self, pixels: &Tensor) -> NetResult<Tensor> {
        let b = pixels.dim(0)?;
        let s = self.config.image_size;
        let mut x = pixels.reshape((b, s, s, 3))?;
        for conv in &self.convs {
            x = patch_merge(&x, conv)?.relu()?;
        }
        let flat = x.flatten_from(1)?;
        Ok(self.image_out.forward(&flat)?.relu()?)
    }

    /// Word-id rows [B, L] (as f32) → the GRU's last state [B, text_features]. Padding steps
    /// leave the state as it was, so an instruction's features do not depend on its padding.
    fn text(&self, ids: &Tensor) -> NetResult<Tensor> {
        let (b, l) = ids.dims2()?;
        let vocab = self.config.vocabulary_size();
        let ids = ids
            .clamp(0f32, (vocab - 1) as f32)?
            .round()?
            .to_dtype(DType::U32)?;
        // 1 where a word is, 0 on padding: [B, L, 1].
        let present = ids.ne(0u32)?.to_dtype(self.words.dtype())?.unsqueeze(2)?;
        let embedded = self
            .words
            .as_tensor()
            .embedding(&ids.flatten_all()?)?
            .reshape((b * l, self.config.word_dim))?;
        let h_dim = self.config.text_features;
        let projected = self
            .gru
            .input
            .forward(&embedded)?
            .reshape((b, l, 3 * h_dim))?;
        let mut h = Tensor::zeros((b, h_dim), self.words.dtype(), &Device::Cpu)?;
        for t in 0..l {
            let x = projected.narrow(1, t, 1)?.squeeze(1)?;
            let hh = self.gru.hidden.forward(&h)?;
            let r = sigmoid(&(x.narrow(1, 0, h_dim)? + hh.narrow(1, 0, h_dim)?)?)?;
            let z = sigmoid(&(x.narrow(1, h_dim, h_dim)? + hh.narrow(1, h_dim, h_dim)?)?)?;
            let n = (x.narrow(1, 2 * h_dim, h_dim)? + (r * hh.narrow(1, 2 * h_dim, h_dim)?)?)?
                .tanh()?;
            let next = ((z.affine(-1.0, 1.0)? * n)? + (&z * &h)?)?;
            let m = present.narrow(1, t, 1)?.squeeze(1)?;
            h = (m.broadcast_mul(&next)? + m.affine(-1.0, 1.0)?.broadcast_mul(&h)?)?;
        }
        Ok(h)
    }

    /// Observation rows [B, obs_dim] (proprioception already normalised) → features
    /// [B, feature_dim].
    pub fn forward(&self, obs: &Tensor) -> NetResult<Tensor> {
        let c = &self.config;
        let proprio = obs.narrow(D::Minus1, 0, c.proprio_dim)?;
        let ids = obs.narrow(D::Minus1, c.proprio_dim, c.max_tokens)?;
        let pixels = obs.narrow(
            D::Minus1,
            c.proprio_dim + c.max_tokens,
            3 * c.image_size * c.image_size,
        )?;
        let text = self.text(&ids)?;
        let image = self.image(&pixels)?;
        Ok(Tensor::cat(&[&proprio, &text, &image], D::Minus1)?)
    }

    /// Trainable parameters named `{prefix}.conv.{i}.*`, `{prefix}.image.*`, `{prefix}.words`,
    /// `{prefix}.gru.{input,hidden}.*`.
    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut vars = Vec::new();
        let linear = |vars: &mut Vec<(String, Var)>, name: &str, l: &Linear| {
            vars.push((format!("{prefix}.{name}.weight"), l.weight.clone()));
            vars.push((format!("{prefix}.{name}.bias"), l.bias.clone()));
        };
        for (i, conv) in self.convs.iter().enumerate() {
            linear(&mut vars, &format!("conv.{i}"), conv);
        }
        linear(&mut vars, "image", &self.image_out);
        vars.push((format!("{prefix}.words"), self.words.clone()));
        linear(&mut vars, "gru.input", &self.gru.input);
        linear(&mut vars, "gru.hidden", &self.gru.hidden);
        vars
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> VlaEncoderConfig {
        VlaEncoderConfig {
            proprio_dim: 3,
            max_tokens: 4,
            image_size: 8,
            vocabulary: vec!["box".into(), "put".into(), "the".into()],
            conv_channels: vec![4, 4],
            image_features: 6,
            word_dim: 5,
            text_features: 7,
        }
    }

    fn row(c: &VlaEncoderConfig, ids: [f32; 4], pixel: f32) -> Vec<f32> {
        let mut r = vec![0.1, -0.2, 0.3];
        r.extend(ids);
        r.extend(std::iter::repeat_n(pixel, 3 * c.image_size * c.image_size));
        r
    }

    #[test]
    fn features_see_proprioception_words_and_image_and_ignore_padding() {
        let c = tiny();
        let enc = VlaEncoder::new(&c, &mut SplitMix64::new(1), DType::F32).unwrap();
        let rows = [
            row(&c, [3.0, 4.0, 2.0, 0.0], 0.5),
            row(&c, [3.0, 4.0, 2.0, 0.0], 0.5),
            row(&c, [3.0, 4.0, 4.0, 0.0], 0.5),
            row(&c, [3.0, 4.0, 2.0, 0.0], 0.9),
        ];
        let x = Tensor::from_vec(rows.concat(), (4, c.obs_dim()), &Device::Cpu).unwrap();
        let f: Vec<Vec<f32>> = enc.forward(&x).unwrap().to_vec2().unwrap();
        assert_eq!(f[0].len(), c.feature_dim());
        assert_eq!(&f[0][..3], &[0.1, -0.2, 0.3]);
        let text = 3..3 + c.text_features;
        let image = 3 + c.text_features..c.feature_dim();
        assert_eq!(f[0], f[1]);
        assert_ne!(f[0][text.clone()], f[2][text.clone()], "another word");
        assert_eq!(f[0][image.clone()], f[2][image.clone()]);
        assert_ne!(f[0][image.clone()], f[3][image], "another image");
        assert_eq!(f[0][text.clone()], f[3][text]);
        // Ids out of range (a corrupted row) are clamped, not an error.
        let bad = row(&c, [99.0, -3.0, 2.0, 0.0], 0.5);
        let x = Tensor::from_vec(bad, (1, c.obs_dim()), &Device::Cpu).unwrap();
        assert!(enc.forward(&x).is_ok());
    }

    #[test]
    fn every_part_gets_a_gradient() {
        let c = tiny();
        let enc = VlaEncoder::new(&c, &mut SplitMix64::new(2), DType::F32).unwrap();
        let rows = [
            row(&c, [3.0, 2.0, 0.0, 0.0], 0.3),
            row(&c, [4.0, 1.0, 2.0, 0.0], 0.7),
        ];
        let x = Tensor::from_vec(rows.concat(), (2, c.obs_dim()), &Device::Cpu).unwrap();
        let loss = enc.forward(&x).unwrap().sqr().unwrap().sum_all().unwrap();
        let grads = loss.backward().unwrap();
        for (name, var) in enc.named_vars("enc") {
            let g = grads
                .get(var.as_tensor())
                .unwrap_or_else(|| panic!("{name}: no gradient"));
            let norm: f32 = g.sqr().unwrap().sum_all().unwrap().to_scalar().unwrap();
            assert!(norm > 0.0, "{name}: zero gradient");
        }
    }

    #[test]
    fn a_vla_actor_critic_normalises_only_proprioception_and_its_weights_round_trip() {
        use crate::{ActorCritic, ActorCriticConfig};
        let c = tiny();
        let mut config = ActorCriticConfig::with_hidden(&[8]);
        config.policy.vla = Some(c.clone());
        let mut ac = ActorCritic::new(c.obs_dim(), 2, &config).unwrap();
        assert_eq!(ac.normalized_dim(), 3);
        assert_eq!(ac.obs_norm.as_ref().map(|n| n.dim()), Some(3));
        let rows = [
            row(&c, [3.0, 4.0, 2.0, 0.0], 0.5),
            row(&c, [2.0, 0.0, 0.0, 0.0], 0.9),
        ]
        .concat();
        let mut shifted = rows.clone();
        shifted[0] += 1.0;
        ac.update_obs_norm(&shifted).unwrap();
        let input = ac.input_rows(&rows).unwrap();
        // Word ids and pixels pass through untouched; the proprioception is whitened.
        assert_eq!(&input[3..c.obs_dim()], &rows[3..c.obs_dim()]);
        assert_ne!(input[0], rows[0]);
        let actions = ac.act_deterministic(&rows).unwrap();
        assert_eq!(actions.len(), 4);
        assert_eq!(ac.values(&rows).unwrap().len(), 2);
        // The encoder's weights travel with the policy's.
        let names: Vec<String> = ac.named_vars().into_iter().map(|(n, _)| n).collect();
        assert!(
            names.iter().any(|n| n == "policy.encoder.words"),
            "{names:?}"
        );
        let bytes = ac.weights_safetensors().unwrap();
        let mut other = config.clone();
        other.init_seed = 9;
        let mut copy = ActorCritic::new(c.obs_dim(), 2, &other).unwrap();
        copy.obs_norm.clone_from(&ac.obs_norm);
        assert_ne!(copy.act_deterministic(&rows).unwrap(), actions);
        copy.load_weights_safetensors(&bytes).unwrap();
        assert_eq!(copy.act_deterministic(&rows).unwrap(), actions);
    }

    #[test]
    fn a_patch_merge_sees_exactly_its_two_by_two_patch() {
        // One output channel that sums the patch's red values: weights 1 on taps' channel 0.
        let mut rng = SplitMix64::new(3);
        let layer = Linear::new(12, 1, 1.0, &mut rng, DType::F32).unwrap();
        let w: Vec<f32> = (0..12)
            .map(|i| if i % 3 == 0 { 1.0 } else { 0.0 })
            .collect();
        layer
            .weight
            .set(&Tensor::from_vec(w, (1, 12), &Device::Cpu).unwrap())
            .unwrap();
        layer
            .bias
            .set(&Tensor::zeros(1, DType::F32, &Device::Cpu).unwrap())
            .unwrap();
        // A 4 × 4 image whose red value is 10 · row + column.
        let img: Vec<f32> = (0..16)
            .flat_map(|p| [(10 * (p / 4) + p % 4) as f32, 0.5, 0.5])
            .collect();
        let x = Tensor::from_vec(img, (1, 4, 4, 3), &Device::Cpu).unwrap();
        let y: Vec<f32> = patch_merge(&x, &layer)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        // Patch (0, 0): 0 + 1 + 10 + 11; (0, 1): 2 + 3 + 12 + 13; (1, 0): 20 + 21 + 30 + 31.
        assert_eq!(y, vec![22.0, 30.0, 102.0, 110.0]);
    }

    #[test]
    fn a_bad_layout_is_refused_by_name() {
        let mut c = tiny();
        c.image_size = 6;
        let e = c.check().unwrap_err();
        assert!(e.contains("image_size"), "{e}");
        let mut c = tiny();
        c.vocabulary = vec!["the".into(), "box".into()];
        assert!(c.check().unwrap_err().contains("vocabulary"));
    }
}
