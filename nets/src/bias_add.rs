//! x + b with b broadcast over rows, as one custom op. Candle's `broadcast_add` backward sums
//! the output gradient over the batch with a strided reduction on one thread; here the bias
//! gradient is a row-chunked column sum over rayon's threads. The chunk partials are added in
//! chunk order, so the result does not depend on scheduling or thread count (checkpoint resumes
//! are bit-exact).

use crate::fused_elu::{contiguous_f32, CHUNK};
use candle_core::{CpuStorage, CustomOp2, Error, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

struct BiasAdd;

fn dims(x: &Layout, b: &Layout, op: &str) -> Result<(usize, usize)> {
    match (x.shape().dims(), b.shape().dims()) {
        (&[rows, cols], &[n]) if n == cols => Ok((rows, cols)),
        (xs, bs) => Err(Error::Msg(format!(
            "{op}: needs x [rows, cols] and b [cols], got {xs:?} and {bs:?}"
        ))),
    }
}

impl CustomOp2 for BiasAdd {
    fn name(&self) -> &'static str {
        "bias-add"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (_, cols) = dims(l1, l2, self.name())?;
        let x = contiguous_f32(s1, l1, self.name())?;
        let b = contiguous_f32(s2, l2, self.name())?;
        let rows_per_task = (CHUNK / cols).max(1);
        let mut y = vec![0f32; x.len()];
        y.par_chunks_mut(rows_per_task * cols)
            .zip(x.par_chunks(rows_per_task * cols))
            .for_each(|(y, x)| {
                for (y, x) in y.chunks_exact_mut(cols).zip(x.chunks_exact(cols)) {
                    for ((y, &x), &b) in y.iter_mut().zip(x).zip(b) {
                        *y = x + b;
                    }
                }
            });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        _x: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let grad = grad_res.contiguous()?;
        let grad_b = grad.apply_op1_no_bwd(&ColumnSum)?;
        Ok((Some(grad), Some(grad_b.reshape(b.shape())?)))
    }
}

/// Sum over rows of a [rows, cols] tensor, deterministic (see the module comment).
struct ColumnSum;

impl candle_core::CustomOp1 for ColumnSum {
    fn name(&self) -> &'static str {
        "column-sum"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let &[_, cols] = layout.shape().dims() else {
            return Err(Error::Msg(format!(
                "column-sum: needs [rows, cols], got {:?}",
                layout.shape().dims()
            )));
        };
        let g = contiguous_f32(storage, layout, "column-sum")?;
        let rows_per_task = (CHUNK / cols.max(1)).max(1);
        let partials: Vec<Vec<f32>> = g
            .par_chunks(rows_per_task * cols.max(1))
            .map(|block| {
                let mut sum = vec![0f32; cols];
                for row in block.chunks_exact(cols) {
                    for (s, &v) in sum.iter_mut().zip(row) {
                        *s += v;
                    }
                }
                sum
            })
            .collect();
        let mut total = vec![0f32; cols];
        for partial in &partials {
            for (t, p) in total.iter_mut().zip(partial) {
                *t += p;
            }
        }
        Ok((CpuStorage::F32(total), Shape::from(cols)))
    }
}

/// `x + b` (x [rows, cols], b [cols]) with the fused op where it applies (contiguous f32 on the
/// CPU), candle's `broadcast_add` otherwise.
pub(crate) fn bias_add(x: &Tensor, b: &Tensor) -> Result<Tensor> {
    let fits = x.dtype() == candle_core::DType::F32
        && b.dtype() == candle_core::DType::F32
        && x.rank() == 2
        && b.rank() == 1
        && x.is_contiguous()
        && b.is_contiguous()
        && x.device().is_cpu();
    if fits {
        x.apply_op2(b, BiasAdd)
    } else {
        x.broadcast_add(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn bias_add_matches_broadcast_add_forward_and_backward() -> Result<()> {
        // More rows than one task holds, so the chunked column sum is exercised.
        let (rows, cols) = (CHUNK / 16 + 37, 16);
        let xs: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 7919) % 101) as f32 * 0.01 - 0.5)
            .collect();
        let x = Var::from_vec(xs, (rows, cols), &Device::Cpu)?;
        let b = Var::from_vec(
            (0..cols).map(|i| i as f32 * 0.1).collect(),
            cols,
            &Device::Cpu,
        )?;
        let w = Tensor::arange(0f32, (rows * cols) as f32, &Device::Cpu)?
            .reshape((rows, cols))?
            .affine(1e-4, 0.0)?;
        let fused = bias_add(x.as_tensor(), b.as_tensor())?;
        let reference = x.as_tensor().broadcast_add(b.as_tensor())?;
        let diff = (&fused - &reference)?
            .abs()?
            .max_all()?
            .to_scalar::<f32>()?;
        assert_eq!(diff, 0.0);
        let g_fused = (fused * &w)?.sum_all()?.backward()?;
        let g_ref = (reference * &w)?.sum_all()?.backward()?;
        for var in [&x, &b] {
            let (a, r) = (
                g_fused.get(var.as_tensor()).expect("fused gradient"),
                g_ref.get(var.as_tensor()).expect("reference gradient"),
            );
            let scale = r.abs()?.max_all()?.to_scalar::<f32>()?.max(1.0);
            let diff = (a - r)?.abs()?.max_all()?.to_scalar::<f32>()?;
            assert!(diff <= 1e-6 * scale, "{diff} of {scale}");
        }
        Ok(())
    }

    #[test]
    fn a_wrong_bias_length_is_an_error() -> Result<()> {
        let x = Tensor::zeros((4, 3), candle_core::DType::F32, &Device::Cpu)?;
        let b = Tensor::zeros(5, candle_core::DType::F32, &Device::Cpu)?;
        assert!(bias_add(&x, &b).is_err());
        Ok(())
    }
}
