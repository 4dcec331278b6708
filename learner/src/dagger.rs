//! DAgger's two learner-side pieces (paper Sec. 3.3): the aggregated dataset of (student state,
//! teacher action) rows, bounded and on disk so a killed learner loses no round it saved, and the
//! student's regression onto it.
//!
//! The learner owns the dataset (not the dagger-server): it is what the learner trains on, it is
//! checkpointed with the learner's run, and the dagger-server stays a stateless label service
//! that can be restarted or replicated freely.

use std::fs;
use std::path::{Path, PathBuf};

use candle_core::Tensor;
use lhm_nets::adam::{clip_global_norm, gradients};
use lhm_nets::checkpoint::write_atomic;
use lhm_nets::{ActorCritic, Adam, AdamConfig, SplitMix64};
use serde::{Deserialize, Serialize};

use crate::error::{LearnerError, LearnerResult};

const INDEX_FILE: &str = "index.json";

/// What `index.json` records: the row layout and the shards in the order they were added.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Index {
    obs_dim: usize,
    act_dim: usize,
    /// Shard sequence numbers, oldest first, with their row counts.
    shards: Vec<(u64, usize)>,
    next_shard: u64,
}

/// The aggregated dataset: rows of `obs_dim` observations followed by `act_dim` teacher actions,
/// in shards of one aggregation round each (`shard-<n>.f32`, little-endian f32), listed by
/// `index.json`. Each file is written to a temporary name and renamed, the shard before the index
/// that lists it, so a crash at any point leaves the last complete state; a shard no index lists
/// (a crash between the two renames) is ignored and removed on the next open. Past `capacity`
/// rows, whole oldest shards are dropped (the newest round is always kept).
pub struct DaggerDataset {
    dir: PathBuf,
    index: Index,
    capacity: usize,
    /// Every row of every listed shard, oldest first.
    rows: Vec<f32>,
}

impl DaggerDataset {
    /// Opens the dataset in `dir` (created empty if absent). An existing one must have the same
    /// row layout.
    pub fn open(
        dir: &Path,
        obs_dim: usize,
        act_dim: usize,
        capacity: usize,
    ) -> LearnerResult<Self> {
        if obs_dim == 0 || act_dim == 0 || capacity == 0 {
            return Err(LearnerError::Invalid(format!(
                "dataset layout {obs_dim} + {act_dim} with capacity {capacity}: all must be positive"
            )));
        }
        fs::create_dir_all(dir).map_err(io(dir))?;
        let index_path = dir.join(INDEX_FILE);
        let index = match fs::read(&index_path) {
            Ok(bytes) => {
                let index: Index =
                    serde_json::from_slice(&bytes).map_err(|e| LearnerError::Corrupt {
                        path: index_path.clone(),
                        message: e.to_string(),
                    })?;
                if (index.obs_dim, index.act_dim) != (obs_dim, act_dim) {
                    return Err(LearnerError::Corrupt {
                        path: index_path,
                        message: format!(
                            "rows of {} + {} values, this run's are {obs_dim} + {act_dim}",
                            index.obs_dim, index.act_dim
                        ),
                    });
                }
                index
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Index {
                obs_dim,
                act_dim,
                shards: Vec::new(),
                next_shard: 0,
            },
            Err(e) => return Err(io(&index_path)(e)),
        };
        let width = obs_dim + act_dim;
        let mut rows = Vec::new();
        for &(n, count) in &index.shards {
            let path = shard_path(dir, n);
            let bytes = fs::read(&path).map_err(io(&path))?;
            // The count comes from a file: an absurd one is corruption, not an overflow.
            let expected = count.checked_mul(width * 4);
            if expected != Some(bytes.len()) {
                return Err(LearnerError::Corrupt {
                    path,
                    message: format!(
                        "{} bytes, the index says {count} rows of {width} f32",
                        bytes.len()
                    ),
                });
            }
            rows.extend(
                bytes
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            );
        }
        let dataset = Self {
            dir: dir.to_owned(),
            index,
            capacity,
            rows,
        };
        dataset.remove_strays()?;
        Ok(dataset)
    }

    /// Rows held.
    pub fn len(&self) -> usize {
        self.rows.len() / self.width()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Aggregation rounds held (shards).
    pub fn rounds(&self) -> usize {
        self.index.shards.len()
    }

    fn width(&self) -> usize {
        self.index.obs_dim + self.index.act_dim
    }

    /// Row `i`: (observation, teacher action).
    pub fn row(&self, i: usize) -> (&[f32], &[f32]) {
        let w = self.width();
        let r = &self.rows[i * w..(i + 1) * w];
        r.split_at(self.index.obs_dim)
    }

    /// Adds one aggregation round: `obs` (rows × obs_dim) with the teachers' `actions`
    /// (rows × act_dim). Saved before it returns; then the oldest rounds beyond the capacity
    /// are dropped.
    pub fn append(&mut self, obs: &[f32], actions: &[f32]) -> LearnerResult<()> {
        let (od, ad) = (self.index.obs_dim, self.index.act_dim);
        let n = obs.len() / od;
        if obs.len() != n * od || actions.len() != n * ad || n == 0 {
            return Err(LearnerError::Invalid(format!(
                "a round of {} observation and {} action values is not a positive number of \
                 {od} + {ad} rows",
                obs.len(),
                actions.len()
            )));
        }
        if obs.iter().chain(actions).any(|x| !x.is_finite()) {
            return Err(LearnerError::Invalid(
                "a round with a non-finite value".into(),
            ));
        }
        let mut round = Vec::with_capacity(n * (od + ad));
        for i in 0..n {
            round.extend_from_slice(&obs[i * od..(i + 1) * od]);
            round.extend_from_slice(&actions[i * ad..(i + 1) * ad]);
        }
        let seq = self.index.next_shard;
        let bytes: Vec<u8> = round.iter().flat_map(|x| x.to_le_bytes()).collect();
        write_atomic(&shard_path(&self.dir, seq), &bytes, "dagger-shard")?;
        let mut index = self.index.clone();
        index.shards.push((seq, n));
        index.next_shard = seq + 1;
        // Drop the oldest rounds while the rest still holds more than the capacity.
        let mut total: usize = index.shards.iter().map(|s| s.1).sum();
        let mut dropped = Vec::new();
        while index.shards.len() > 1 && total > self.capacity {
            let (old, count) = index.shards.remove(0);
            total -= count;
            dropped.push((old, count));
        }
        let text = serde_json::to_vec_pretty(&index)
            .map_err(|e| LearnerError::Invalid(format!("dataset index: {e}")))?;
        write_atomic(&self.dir.join(INDEX_FILE), &text, "dagger-index")?;
        // Only now is the new state saved; the dropped files are garbage.
        self.index = index;
        let dropped_rows: usize = dropped.iter().map(|d| d.1).sum();
        self.rows.drain(..dropped_rows * self.width());
        self.rows.extend(round);
        for (old, _) in dropped {
            let path = shard_path(&self.dir, old);
            fs::remove_file(&path).map_err(io(&path))?;
        }
        Ok(())
    }

    /// Removes shard files the index does not list (left by a crash between writing a shard and
    /// the index that lists it) and temporary files.
    fn remove_strays(&self) -> LearnerResult<()> {
        let listed: Vec<PathBuf> = self
            .index
            .shards
            .iter()
            .map(|&(n, _)| shard_path(&self.dir, n))
            .collect();
        for entry in fs::read_dir(&self.dir).map_err(io(&self.dir))? {
            let path = entry.map_err(io(&self.dir))?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            let stray_shard = name.starts_with("shard-") && !listed.contains(&path);
            // `write_atomic`'s temporaries: `.<name>.tmp-<pid>`.
            let temporary = name.starts_with('.') && name.contains(".tmp-");
            if stray_shard || temporary {
                fs::remove_file(&path).map_err(io(&path))?;
            }
        }
        Ok(())
    }
}

fn shard_path(dir: &Path, n: u64) -> PathBuf {
    dir.join(format!("shard-{n:08}.f32"))
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> LearnerError + '_ {
    move |source| LearnerError::Io {
        path: path.to_owned(),
        source,
    }
}

/// A DAgger run's settings: the mixing rate β and its schedule, the dataset's bound, the
/// regression.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaggerConfig {
    /// β of the first round: the probability that a step executes the teachers' action instead
    /// of the student's (Ross et al. 2011 start from the expert alone, β = 1).
    pub teacher_mix: f32,
    /// β is multiplied by this after every round (β_k = teacher_mix · decay^k).
    pub teacher_mix_decay: f32,
    /// Rows the aggregated dataset keeps; past it the oldest rounds are dropped.
    pub capacity: usize,
    pub regression: StudentConfig,
}

impl Default for DaggerConfig {
    fn default() -> Self {
        Self {
            teacher_mix: 1.0,
            // β below 0.1 after 45 rounds: the student drives most steps well inside a
            // laptop-sized stage of a few hundred rounds.
            teacher_mix_decay: 0.95,
            // ~330 floats a row: 100k rows are ~130 MB on disk and in memory.
            capacity: 100_000,
            regression: StudentConfig::default(),
        }
    }
}

impl DaggerConfig {
    /// β for the rollouts of round `round` (0-based).
    pub fn teacher_mix_at(&self, round: u64) -> f32 {
        let k = i32::try_from(round).unwrap_or(i32::MAX);
        (self.teacher_mix * self.teacher_mix_decay.powi(k)).clamp(0.0, 1.0)
    }

    pub fn check(&self) -> Result<(), String> {
        if !(0.0..=1.0).contains(&self.teacher_mix)
            || !(0.0..=1.0).contains(&self.teacher_mix_decay)
        {
            return Err(format!(
                "dagger.teacher_mix ({}) and dagger.teacher_mix_decay ({}) must lie in [0, 1]",
                self.teacher_mix, self.teacher_mix_decay
            ));
        }
        if self.capacity == 0 || self.regression.epochs == 0 || self.regression.minibatch_size == 0
        {
            return Err(
                "dagger.capacity, dagger.regression.epochs and dagger.regression.minibatch_size \
                 must be at least 1"
                    .into(),
            );
        }
        Ok(())
    }
}

/// Settings of the student's regression.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StudentConfig {
    pub adam: AdamConfig,
    /// Rows trained on per round, in multiples of the newest round's rows, drawn uniformly from
    /// the whole dataset.
    pub epochs: usize,
    pub minibatch_size: usize,
    pub max_grad_norm: f64,
}

impl Default for StudentConfig {
    fn default() -> Self {
        Self {
            adam: AdamConfig {
                lr: 1e-3,
                ..AdamConfig::default()
            },
            epochs: 4,
            minibatch_size: 512,
            max_grad_norm: 1.0,
        }
    }
}

/// Mean squared error of the student's mean action against the teachers' labels, before and
/// after a round of training.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StudentStats {
    pub loss_before: f64,
    pub loss_after: f64,
    pub minibatches: usize,
}

/// Trains a student's policy mean by regression onto the aggregated teacher actions.
pub struct StudentTrainer {
    config: StudentConfig,
    adam: Adam,
}

impl StudentTrainer {
    pub fn new(config: StudentConfig, student: &ActorCritic) -> LearnerResult<Self> {
        let vars: Vec<_> = student
            .policy
            .named_vars("policy")
            .into_iter()
            .map(|v| v.1)
            .collect();
        Ok(Self {
            adam: Adam::new(config.adam.clone(), &vars)?,
            config,
        })
    }

    /// Mean squared action error over all of `data`.
    pub fn loss(&self, student: &ActorCritic, data: &DaggerDataset) -> LearnerResult<f64> {
        self.loss_on(student, data, &(0..data.len()).collect::<Vec<_>>())
    }

    /// Mean squared action error over the rows `rows` of `data`.
    fn loss_on(
        &self,
        student: &ActorCritic,
        data: &DaggerDataset,
        rows: &[usize],
    ) -> LearnerResult<f64> {
        let mut total = 0.0;
        for chunk in rows.chunks(4096) {
            let (obs, labels) = gather(data, chunk);
            let mse = mse(student, &obs, &labels, chunk.len())?;
            total += mse.to_scalar::<f32>()? as f64 * chunk.len() as f64;
        }
        Ok(total / rows.len().max(1) as f64)
    }

    /// One round: folds the newest round's observations into the student's normaliser, then
    /// `epochs` × the newest round's rows, drawn uniformly from the whole aggregated dataset, in
    /// minibatches. Each round costs the same however large the dataset has grown (full passes
    /// over it took 13.6 s a round at 100k rows, against ~1 s of collection); every row stays
    /// equally likely to be trained on. The losses before and after are measured on the same
    /// uniform sample of at most [`LOSS_ROWS`] rows.
    pub fn train_round(
        &mut self,
        student: &mut ActorCritic,
        data: &DaggerDataset,
        newest_round_rows: usize,
        rng: &mut SplitMix64,
    ) -> LearnerResult<StudentStats> {
        if data.is_empty() {
            return Err(LearnerError::Invalid("the DAgger dataset is empty".into()));
        }
        let newest = newest_round_rows.clamp(1, data.len());
        if student.obs_norm.is_some() {
            let (obs, _) = gather(
                data,
                &((data.len() - newest)..data.len()).collect::<Vec<_>>(),
            );
            student.update_obs_norm(&obs)?;
        }
        let probe: Vec<usize> = if data.len() <= LOSS_ROWS {
            (0..data.len()).collect()
        } else {
            (0..LOSS_ROWS).map(|_| rng.below(data.len())).collect()
        };
        let loss_before = self.loss_on(student, data, &probe)?;
        let vars: Vec<_> = student
            .policy
            .named_vars("policy")
            .into_iter()
            .map(|v| v.1)
            .collect();
        let draws: Vec<usize> = (0..self.config.epochs.max(1) * newest)
            .map(|_| rng.below(data.len()))
            .collect();
        let mut minibatches = 0;
        for mb in draws.chunks(self.config.minibatch_size.max(1)) {
            let (obs, labels) = gather(data, mb);
            let loss = mse(student, &obs, &labels, mb.len())?;
            let store = loss.backward()?;
            let mut grads = gradients(&vars, &store)?;
            clip_global_norm(&mut grads, self.config.max_grad_norm);
            self.adam.step(&vars, &grads)?;
            minibatches += 1;
        }
        Ok(StudentStats {
            loss_before,
            loss_after: self.loss_on(student, data, &probe)?,
            minibatches,
        })
    }
}

/// Rows on which a round's losses are measured (all of them while the dataset is smaller).
pub const LOSS_ROWS: usize = 8192;

/// The rows `rows` of `data` as (observations, labels), row-major.
fn gather(data: &DaggerDataset, rows: &[usize]) -> (Vec<f32>, Vec<f32>) {
    let mut obs = Vec::with_capacity(rows.len() * data.index.obs_dim);
    let mut labels = Vec::with_capacity(rows.len() * data.index.act_dim);
    for &i in rows {
        let (o, a) = data.row(i);
        obs.extend_from_slice(o);
        labels.extend_from_slice(a);
    }
    (obs, labels)
}

/// Mean over rows of the squared error summed over action dimensions.
fn mse(student: &ActorCritic, obs: &[f32], labels: &[f32], n: usize) -> LearnerResult<Tensor> {
    let mean = student.policy.mean(&student.input_tensor(obs)?)?;
    let target = Tensor::from_slice(labels, (n, student.act_dim()), mean.device())?;
    Ok(((mean - target)?.sqr()?.sum(1)?.mean_all())?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lhm_nets::ActorCriticConfig;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("lhm-dagger-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    /// A teacher that is a fixed linear map of the observation, clipped to the action range.
    fn teacher(obs: &[f32]) -> Vec<f32> {
        obs.chunks(4)
            .flat_map(|o| {
                [
                    (0.5 * o[0] - 0.3 * o[1]).clamp(-1.0, 1.0),
                    (0.2 * o[2] + 0.4 * o[3]).clamp(-1.0, 1.0),
                ]
            })
            .collect()
    }

    fn states(n: usize, rng: &mut SplitMix64) -> Vec<f32> {
        (0..n * 4).map(|_| rng.uniform(-2.0, 2.0) as f32).collect()
    }

    #[test]
    fn rounds_survive_reopening_and_the_oldest_go_past_the_capacity() {
        let dir = scratch("bounded");
        let mut rng = SplitMix64::new(1);
        let mut d = DaggerDataset::open(&dir, 4, 2, 25).unwrap();
        let first = states(10, &mut rng);
        d.append(&first, &teacher(&first)).unwrap();
        let second = states(10, &mut rng);
        d.append(&second, &teacher(&second)).unwrap();
        assert_eq!((d.len(), d.rounds()), (20, 2));
        assert_eq!(d.row(10).0, &second[..4]);
        assert_eq!(d.row(10).1, &teacher(&second[..4])[..]);
        drop(d);
        let mut d = DaggerDataset::open(&dir, 4, 2, 25).unwrap();
        assert_eq!((d.len(), d.rounds()), (20, 2));
        assert_eq!(d.row(0).0, &first[..4]);
        // A third round: 30 rows > 25, so the first round goes, file and all.
        let third = states(10, &mut rng);
        d.append(&third, &teacher(&third)).unwrap();
        assert_eq!((d.len(), d.rounds()), (20, 2));
        assert_eq!(d.row(0).0, &second[..4]);
        assert!(!shard_path(&dir, 0).exists());
        // A round larger than the capacity is kept whole, alone.
        let big = states(40, &mut rng);
        d.append(&big, &teacher(&big)).unwrap();
        assert_eq!((d.len(), d.rounds()), (40, 1));
        let reopened = DaggerDataset::open(&dir, 4, 2, 25).unwrap();
        assert_eq!(reopened.rows, d.rows);
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_crash_before_the_index_loses_only_that_round_and_bad_files_are_named() {
        let dir = scratch("crash");
        let mut rng = SplitMix64::new(2);
        let mut d = DaggerDataset::open(&dir, 4, 2, 100).unwrap();
        let a = states(5, &mut rng);
        d.append(&a, &teacher(&a)).unwrap();
        drop(d);
        // A shard written but never listed, and a half-written temporary.
        fs::write(shard_path(&dir, 1), [0u8; 24]).unwrap();
        fs::write(dir.join(".index.json.tmp-1234"), b"{").unwrap();
        let d = DaggerDataset::open(&dir, 4, 2, 100).unwrap();
        assert_eq!(d.len(), 5);
        assert!(!shard_path(&dir, 1).exists() && !dir.join(".index.json.tmp-1234").exists());
        drop(d);
        // Another layout is refused by name.
        let e = DaggerDataset::open(&dir, 3, 2, 100)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("index.json") && e.contains("4 + 2"), "{e}");
        // A truncated shard is refused by name.
        let path = shard_path(&dir, 0);
        let bytes = fs::read(&path).unwrap();
        fs::write(&path, &bytes[..bytes.len() - 4]).unwrap();
        let e = DaggerDataset::open(&dir, 4, 2, 100)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("shard-00000000.f32") && e.contains("5 rows"),
            "{e}"
        );
        // Garbage index.
        fs::write(dir.join(INDEX_FILE), b"not json").unwrap();
        let e = DaggerDataset::open(&dir, 4, 2, 100)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("index.json"), "{e}");
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_rounds_are_refused_and_nothing_saved_changes() {
        let dir = scratch("refuse");
        let mut d = DaggerDataset::open(&dir, 4, 2, 100).unwrap();
        assert!(d.append(&[0.0; 7], &[0.0; 4]).is_err());
        assert!(d.append(&[0.0; 4], &[f32::NAN, 0.0]).is_err());
        assert!(d.append(&[], &[]).is_err());
        assert!(d.is_empty());
        assert!(DaggerDataset::open(&dir, 4, 2, 0).is_err());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_student_regresses_onto_the_teacher_and_improves_as_rounds_aggregate() {
        let dir = scratch("student");
        let mut rng = SplitMix64::new(3);
        let mut d = DaggerDataset::open(&dir, 4, 2, 10_000).unwrap();
        let mut student =
            ActorCritic::new(4, 2, &ActorCriticConfig::with_hidden(&[32, 32])).unwrap();
        // Rounds of 400 rows: 20 × 400 rows drawn per round (16 minibatches).
        let config = StudentConfig {
            epochs: 20,
            ..StudentConfig::default()
        };
        let mut trainer = StudentTrainer::new(config, &student).unwrap();
        let held_out = states(500, &mut rng);
        let err = |s: &ActorCritic| {
            let got = s.act_deterministic(&held_out).unwrap();
            let want = teacher(&held_out);
            got.iter()
                .zip(&want)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
                / 500.0
        };
        let initial = err(&student);
        let mut last_after = f64::INFINITY;
        for _ in 0..5 {
            let round = states(400, &mut rng);
            d.append(&round, &teacher(&round)).unwrap();
            let stats = trainer
                .train_round(&mut student, &d, 400, &mut rng)
                .unwrap();
            assert!(stats.loss_after < stats.loss_before, "{stats:?}");
            assert!(stats.minibatches > 0);
            last_after = stats.loss_after;
        }
        let fin = err(&student);
        assert!(fin < 0.1 * initial, "held-out error {initial} -> {fin}");
        assert!(last_after < 0.05, "{last_after}");
        assert_eq!(d.len(), 2000);
        let _ = fs::remove_dir_all(&dir);
    }
}
