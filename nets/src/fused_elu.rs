//! ELU as one custom op with a one-pass backward. Candle's built-in ELU backward makes about
//! eight full-size temporaries (two comparison masks, their casts, products and sums); on the
//! [4096, 1024] activations of the paper-size networks that is a measurable share of a step.
//! The backward uses only the output y: ELU'(x) = 1 where y > 0, y + 1 elsewhere.
//!
//! Both passes are split over rayon's threads (the pool the matmuls use) and written so the
//! compiler vectorises them: libm's scalar `expf` on one thread made the forward pass ~10 % of
//! a PPO step while the other core idled.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Error, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// Elements per parallel task: large enough that scheduling is noise, small enough to balance.
pub(crate) const CHUNK: usize = 1 << 15;

/// e^x for x ≤ 0, branch-free so that loops over it vectorise: x = n·ln2 + r with |r| ≤ ln2/2,
/// e^r by its degree-6 Taylor polynomial (relative error < 2e-7 there), 2^n through the
/// exponent bits. Below -87 the result flushes to 0 (e^-87 ≈ 1.6e-38).
#[inline(always)]
fn exp_nonpositive(x: f32) -> f32 {
    let x = x.max(-87.0);
    let n = (x * std::f32::consts::LOG2_E).round();
    // ln 2 split in two so that n·ln2 is exact enough for |n| ≤ 126 (Cody-Waite).
    let r = x - n * 0.693_145_75 - n * 1.428_606_8e-6;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let scale = f32::from_bits(((n as i32 + 127) as u32) << 23);
    p * scale
}

#[inline(always)]
fn elu_value(v: f32) -> f32 {
    let negative = exp_nonpositive(v.min(0.0)) - 1.0;
    if v > 0.0 {
        v
    } else {
        negative
    }
}

pub(crate) fn contiguous_f32<'a>(
    storage: &'a CpuStorage,
    layout: &Layout,
    op: &str,
) -> Result<&'a [f32]> {
    let (start, end) = layout
        .contiguous_offsets()
        .ok_or_else(|| Error::Msg(format!("{op}: input must be contiguous")))?;
    match storage {
        CpuStorage::F32(values) => Ok(&values[start..end]),
        other => Err(Error::Msg(format!(
            "{op}: f32 only, got {:?}",
            other.dtype()
        ))),
    }
}

struct FusedElu;

impl CustomOp1 for FusedElu {
    fn name(&self) -> &'static str {
        "fused-elu"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = contiguous_f32(storage, layout, self.name())?;
        let mut y = vec![0f32; x.len()];
        y.par_chunks_mut(CHUNK)
            .zip(x.par_chunks(CHUNK))
            .for_each(|(y, x)| {
                for (y, &v) in y.iter_mut().zip(x) {
                    *y = elu_value(v);
                }
            });
        Ok((CpuStorage::F32(y), layout.shape().clone()))
    }

    fn bwd(&self, _arg: &Tensor, res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(res.apply_op2_no_bwd(
            &grad_res.contiguous()?,
            &FusedEluBackward,
        )?))
    }
}

/// (y, dL/dy) → dL/dx. Never differentiated again (the AMP gradient penalty builds its input
/// gradient from ordinary ops instead).
struct FusedEluBackward;

impl CustomOp2 for FusedEluBackward {
    fn name(&self) -> &'static str {
        "fused-elu-backward"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let y = contiguous_f32(s1, l1, self.name())?;
        let g = contiguous_f32(s2, l2, self.name())?;
        if y.len() != g.len() {
            return Err(Error::Msg(format!(
                "{}: {} outputs but {} gradients",
                self.name(),
                y.len(),
                g.len()
            )));
        }
        let mut dx = vec![0f32; y.len()];
        dx.par_chunks_mut(CHUNK)
            .zip(y.par_chunks(CHUNK).zip(g.par_chunks(CHUNK)))
            .for_each(|(dx, (y, g))| {
                for ((dx, &y), &g) in dx.iter_mut().zip(y).zip(g) {
                    *dx = if y > 0.0 { g } else { g * (y + 1.0) };
                }
            });
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

/// ELU(α = 1) with the fused op where it applies (contiguous f32 on the CPU), candle's otherwise.
pub(crate) fn elu(z: &Tensor) -> Result<Tensor> {
    if z.dtype() == candle_core::DType::F32 && z.is_contiguous() && z.device().is_cpu() {
        z.apply_op1(FusedElu)
    } else {
        z.elu(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn exp_nonpositive_matches_libm_to_a_few_ulps() {
        let mut worst = 0f64;
        for i in 0..=200_000 {
            let x = -90.0 * i as f32 / 200_000.0;
            let (fast, exact) = (exp_nonpositive(x) as f64, (x as f64).exp());
            if exact > 1e-37 {
                worst = worst.max(((fast - exact) / exact).abs());
            } else {
                assert!(fast < 1e-36, "exp({x}) = {fast}");
            }
        }
        assert!(worst < 5e-7, "relative error {worst}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
    }

    #[test]
    fn fused_elu_matches_candle_elu_forward_and_backward() {
        let x: Vec<f32> = (0..64).map(|i| (i as f32 - 31.5) * 0.11).collect();
        let var = Var::from_vec(x, (8, 8), &Device::Cpu).unwrap();
        let weights = Tensor::arange(0f32, 64.0, &Device::Cpu)
            .unwrap()
            .reshape((8, 8))
            .unwrap();
        let fused = elu(var.as_tensor()).unwrap();
        let reference = var.as_tensor().elu(1.0).unwrap();
        let diff = (&fused - &reference)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(diff < 1e-6, "{diff}");
        let g_fused = (fused * &weights)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let g_ref = (reference * &weights)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let a = g_fused.get(var.as_tensor()).unwrap();
        let b = g_ref.get(var.as_tensor()).unwrap();
        let diff = (a - b)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(diff < 1e-4, "{diff}");
    }
}
