//! Running mean / variance of observations, merged batch by batch (Chan et al.'s parallel form
//! of Welford's update), used to whiten network inputs.

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::{NetError, NetResult};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunningMeanStd {
    mean: Vec<f64>,
    /// Population variance of everything seen so far.
    var: Vec<f64>,
    count: f64,
    /// Normalised values are clipped to [-clip, clip].
    pub clip: f64,
    /// Added to the variance before the square root, so constant features do not blow up.
    pub epsilon: f64,
}

impl RunningMeanStd {
    pub fn new(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 0.0,
            clip: 5.0,
            epsilon: 1e-5,
        }
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    pub fn var(&self) -> &[f64] {
        &self.var
    }

    pub fn count(&self) -> f64 {
        self.count
    }

    /// Folds a batch of rows (row-major, `dim` wide) into the statistics.
    pub fn update(&mut self, rows: &[f32]) -> NetResult<()> {
        let dim = self.dim();
        if dim == 0 || rows.len() % dim != 0 {
            return Err(NetError::RaggedRows {
                len: rows.len(),
                width: dim,
            });
        }
        let n = (rows.len() / dim) as f64;
        if n == 0.0 {
            return Ok(());
        }
        let mut batch_mean = vec![0.0f64; dim];
        for row in rows.chunks_exact(dim) {
            for (m, &x) in batch_mean.iter_mut().zip(row) {
                *m += x as f64;
            }
        }
        batch_mean.iter_mut().for_each(|m| *m /= n);
        let mut batch_var = vec![0.0f64; dim];
        for row in rows.chunks_exact(dim) {
            for ((v, &x), m) in batch_var.iter_mut().zip(row).zip(&batch_mean) {
                *v += (x as f64 - m).powi(2);
            }
        }
        batch_var.iter_mut().for_each(|v| *v /= n);

        let total = self.count + n;
        for i in 0..dim {
            let delta = batch_mean[i] - self.mean[i];
            let m2 = self.var[i] * self.count
                + batch_var[i] * n
                + delta * delta * self.count * n / total;
            self.mean[i] += delta * n / total;
            self.var[i] = m2 / total;
        }
        self.count = total;
        Ok(())
    }

    /// (x - mean) / sqrt(var + eps), clipped, for rows of `dim` floats.
    pub fn normalize(&self, rows: &[f32]) -> NetResult<Vec<f32>> {
        let dim = self.dim();
        if dim == 0 || rows.len() % dim != 0 {
            return Err(NetError::RaggedRows {
                len: rows.len(),
                width: dim,
            });
        }
        let inv_std: Vec<f64> = self
            .var
            .iter()
            .map(|v| 1.0 / (v + self.epsilon).sqrt())
            .collect();
        Ok(rows
            .chunks_exact(dim)
            .flat_map(|row| {
                row.iter()
                    .zip(&self.mean)
                    .zip(&inv_std)
                    .map(|((&x, m), s)| ((x as f64 - m) * s).clamp(-self.clip, self.clip) as f32)
            })
            .collect())
    }

    /// Normalised rows as a [rows, dim] tensor.
    pub fn normalize_tensor(&self, rows: &[f32]) -> NetResult<Tensor> {
        let data = self.normalize(rows)?;
        let n = data.len() / self.dim();
        Ok(Tensor::from_vec(data, (n, self.dim()), &Device::Cpu)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_batches_match_whole_data_statistics() {
        let data: Vec<f32> = (0..60)
            .map(|i| ((i * 37) % 11) as f32 * 0.5 - (i % 2) as f32)
            .collect();
        let mut whole = RunningMeanStd::new(3);
        whole.update(&data).unwrap();
        let mut parts = RunningMeanStd::new(3);
        for chunk in data.chunks(9) {
            parts.update(chunk).unwrap();
        }
        for d in 0..3 {
            let col: Vec<f64> = data.iter().skip(d).step_by(3).map(|&x| x as f64).collect();
            let mean = col.iter().sum::<f64>() / col.len() as f64;
            let var = col.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / col.len() as f64;
            assert!((whole.mean()[d] - mean).abs() < 1e-12);
            assert!((whole.var()[d] - var).abs() < 1e-12);
            assert!((parts.mean()[d] - mean).abs() < 1e-12);
            assert!((parts.var()[d] - var).abs() < 1e-12);
        }
        assert_eq!(parts.count(), 20.0);
    }

    #[test]
    fn normalize_whitens_and_clips() {
        let mut norm = RunningMeanStd::new(1);
        norm.update(&[1.0, 3.0]).unwrap(); // mean 2, var 1
        let out = norm.normalize(&[2.0, 3.0, 100.0]).unwrap();
        assert!(out[0].abs() < 1e-6);
        assert!((out[1] - 1.0).abs() < 1e-4);
        assert_eq!(out[2], 5.0);
        assert!(norm.update(&[1.0, 2.0, 3.0]).is_ok());
        assert!(RunningMeanStd::new(2).update(&[1.0, 2.0, 3.0]).is_err());
    }
}
