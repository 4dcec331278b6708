//! Checkpoint files: `<stem>.safetensors` holds every tensor, `<stem>.json` the metadata (format
//! version, kind, tensor manifest, FNV-1a 64 checksum of the safetensors bytes, and a typed
//! payload: configs, counters, normaliser statistics, optimiser step counts, RNG states).
//!
//! Tensor names are plain dotted PyTorch-style names (`policy.mean.layers.0.weight`, weights
//! [out, in]), so a PyTorch user can read the weights with
//! `safetensors.torch.load_file("<stem>.safetensors")` and load them into an `nn.Linear` stack.
//!
//! Both files are written atomically (temporary file in the same directory, fsync, rename, fsync
//! of the directory); the JSON is renamed last, so it is the commit point, and a safetensors
//! file that does not match it is caught by the checksum.

use std::collections::{BTreeMap, HashMap};
use std::ffi::OsString;
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor, Var};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

pub const FORMAT_NAME: &str = "lhm-checkpoint";
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{}: I/O error while {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{}: corrupt checkpoint: {reason}", path.display())]
    Corrupt { path: PathBuf, reason: String },
    #[error("{}: checksum mismatch: metadata records FNV-1a 64 {expected}, file has {actual} (corrupt, or written by a different save)", path.display())]
    Checksum {
        path: PathBuf,
        expected: String,
        actual: String,
    },
    #[error("{}: checkpoint format version {found}, this build reads version {expected}", path.display())]
    Version {
        path: PathBuf,
        found: u32,
        expected: u32,
    },
    #[error("{}: holds a `{found}` checkpoint, expected `{expected}`", path.display())]
    Kind {
        path: PathBuf,
        found: String,
        expected: String,
    },
    #[error("{}: tensor `{name}` is missing", path.display())]
    MissingTensor { path: PathBuf, name: String },
    #[error("{}: tensor `{name}` is {found}, expected {expected}", path.display())]
    Shape {
        path: PathBuf,
        name: String,
        found: String,
        expected: String,
    },
    #[error("{}: does not match this configuration: {what}", path.display())]
    Mismatch { path: PathBuf, what: String },
    #[error("{}: tensor error: {source}", path.display())]
    Tensor {
        path: PathBuf,
        source: candle_core::Error,
    },
}

pub type CheckpointResult<T> = Result<T, CheckpointError>;

/// 64-bit FNV-1a: tiny, dependency-free, and enough to detect accidental corruption.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The two files of the checkpoint at `stem` (`stem` may contain dots; extensions are appended).
#[derive(Debug, Clone)]
pub struct CheckpointPaths {
    pub weights: PathBuf,
    pub meta: PathBuf,
}

impl CheckpointPaths {
    pub fn new(stem: &Path) -> Self {
        let with = |ext: &str| {
            let mut s: OsString = stem.as_os_str().to_owned();
            s.push(ext);
            PathBuf::from(s)
        };
        Self {
            weights: with(".safetensors"),
            meta: with(".json"),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TensorInfo {
    pub dtype: String,
    pub shape: Vec<usize>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Envelope<T> {
    format: String,
    format_version: u32,
    kind: String,
    weights_file: String,
    weights_len: u64,
    weights_fnv1a64: String,
    tensors: BTreeMap<String, TensorInfo>,
    payload: T,
}

fn dtype_name(t: &Tensor) -> String {
    format!("{:?}", t.dtype()).to_lowercase()
}

fn write_atomic(path: &Path, bytes: &[u8]) -> CheckpointResult<()> {
    let io = |action: &'static str| {
        move |source| CheckpointError::Io {
            path: path.to_owned(),
            action,
            source,
        }
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{file_name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut file = File::create(&tmp).map_err(io("creating a temporary file"))?;
        file.write_all(bytes).map_err(io("writing"))?;
        file.sync_all().map_err(io("syncing"))?;
        fs::rename(&tmp, path).map_err(io("renaming the temporary file into place"))?;
        // Make the rename itself durable.
        File::open(&dir)
            .and_then(|d| d.sync_all())
            .map_err(io("syncing the directory"))
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Writes `tensors` and `payload` as the checkpoint at `stem`, replacing any previous one.
pub fn save<T: Serialize>(
    stem: &Path,
    kind: &str,
    tensors: &[(String, Tensor)],
    payload: &T,
) -> CheckpointResult<()> {
    let paths = CheckpointPaths::new(stem);
    let tensor_err = |source| CheckpointError::Tensor {
        path: paths.weights.clone(),
        source,
    };
    // Safetensors wants contiguous data; f32/f64 tensors from the nets always are after this.
    let contiguous: Vec<(String, Tensor)> = tensors
        .iter()
        .map(|(n, t)| Ok((n.clone(), t.contiguous()?)))
        .collect::<candle_core::Result<_>>()
        .map_err(tensor_err)?;
    let bytes = safetensors::serialize(contiguous.iter().map(|(n, t)| (n.as_str(), t)), None)
        .map_err(|e| CheckpointError::Corrupt {
            path: paths.weights.clone(),
            reason: format!("cannot serialise tensors: {e}"),
        })?;
    let envelope = Envelope {
        format: FORMAT_NAME.to_owned(),
        format_version: FORMAT_VERSION,
        kind: kind.to_owned(),
        weights_file: paths
            .weights
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        weights_len: bytes.len() as u64,
        weights_fnv1a64: format!("{:016x}", fnv1a64(&bytes)),
        tensors: contiguous
            .iter()
            .map(|(n, t)| {
                (
                    n.clone(),
                    TensorInfo {
                        dtype: dtype_name(t),
                        shape: t.dims().to_vec(),
                    },
                )
            })
            .collect(),
        payload,
    };
    let json = serde_json::to_vec_pretty(&envelope).map_err(|e| CheckpointError::Corrupt {
        path: paths.meta.clone(),
        reason: format!("cannot serialise metadata: {e}"),
    })?;
    write_atomic(&paths.weights, &bytes)?;
    write_atomic(&paths.meta, &json)
}

/// A checkpoint read back and verified (checksum, manifest); tensors are taken by name.
#[derive(Debug)]
pub struct Loaded<T> {
    pub paths: CheckpointPaths,
    pub payload: T,
    tensors: HashMap<String, Tensor>,
}

impl<T> Loaded<T> {
    /// The tensor `name`, which must have exactly `shape`.
    pub fn tensor(&self, name: &str, shape: &[usize]) -> CheckpointResult<&Tensor> {
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| CheckpointError::MissingTensor {
                path: self.paths.weights.clone(),
                name: name.to_owned(),
            })?;
        if t.dims() != shape {
            return Err(CheckpointError::Shape {
                path: self.paths.weights.clone(),
                name: name.to_owned(),
                found: format!("{:?} {}", t.dims(), dtype_name(t)),
                expected: format!("{shape:?}"),
            });
        }
        Ok(t)
    }

    /// A tensor flattened to f32 values, checked against `shape`.
    pub fn f32_values(&self, name: &str, shape: &[usize]) -> CheckpointResult<Vec<f32>> {
        let t = self.tensor(name, shape)?;
        t.flatten_all()
            .and_then(|t| t.to_dtype(candle_core::DType::F32))
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|source| CheckpointError::Tensor {
                path: self.paths.weights.clone(),
                source,
            })
    }

    /// Copies the stored values into `vars` (same names, shapes and dtypes required).
    pub fn load_into(&self, vars: &[(String, Var)]) -> CheckpointResult<()> {
        for (name, var) in vars {
            let t = self.tensor(name, var.dims())?;
            if t.dtype() != var.dtype() {
                return Err(CheckpointError::Shape {
                    path: self.paths.weights.clone(),
                    name: name.clone(),
                    found: format!("{:?} {}", t.dims(), dtype_name(t)),
                    expected: format!("{:?} {}", var.dims(), dtype_name(var.as_tensor())),
                });
            }
            var.set(t).map_err(|source| CheckpointError::Tensor {
                path: self.paths.weights.clone(),
                source,
            })?;
        }
        Ok(())
    }

    pub fn tensor_names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }
}

/// Reads and verifies the checkpoint at `stem`, which must be of `kind`.
pub fn load<T: DeserializeOwned>(stem: &Path, kind: &str) -> CheckpointResult<Loaded<T>> {
    let paths = CheckpointPaths::new(stem);
    let meta_path = paths.meta.clone();
    let corrupt = |path: &Path, reason: String| CheckpointError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    let json = fs::read(&meta_path).map_err(|source| CheckpointError::Io {
        path: meta_path.clone(),
        action: "reading metadata",
        source,
    })?;
    // Header first with the payload left untyped, so a wrong version or kind is reported as
    // such rather than as a payload parse error.
    let envelope: Envelope<serde_json::Value> = serde_json::from_slice(&json)
        .map_err(|e| corrupt(&meta_path, format!("metadata is not valid: {e}")))?;
    if envelope.format != FORMAT_NAME {
        return Err(corrupt(
            &meta_path,
            format!("format is `{}`, not `{FORMAT_NAME}`", envelope.format),
        ));
    }
    if envelope.format_version != FORMAT_VERSION {
        return Err(CheckpointError::Version {
            path: meta_path,
            found: envelope.format_version,
            expected: FORMAT_VERSION,
        });
    }
    if envelope.kind != kind {
        return Err(CheckpointError::Kind {
            path: meta_path,
            found: envelope.kind,
            expected: kind.to_owned(),
        });
    }
    let payload: T =
        serde_json::from_value(envelope.payload).map_err(|e| CheckpointError::Mismatch {
            path: meta_path.clone(),
            what: format!("metadata payload does not fit this build: {e}"),
        })?;

    let weights_path = paths.weights.clone();
    let bytes = fs::read(&weights_path).map_err(|source| CheckpointError::Io {
        path: weights_path.clone(),
        action: "reading weights",
        source,
    })?;
    if bytes.len() as u64 != envelope.weights_len {
        return Err(corrupt(
            &weights_path,
            format!(
                "file is {} bytes, metadata records {} (truncated or replaced)",
                bytes.len(),
                envelope.weights_len
            ),
        ));
    }
    let actual = format!("{:016x}", fnv1a64(&bytes));
    if actual != envelope.weights_fnv1a64 {
        return Err(CheckpointError::Checksum {
            path: weights_path,
            expected: envelope.weights_fnv1a64,
            actual,
        });
    }
    let tensors = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu).map_err(|e| {
        corrupt(
            &weights_path,
            format!("not a readable safetensors file: {e}"),
        )
    })?;
    if tensors.len() != envelope.tensors.len() {
        return Err(corrupt(
            &weights_path,
            format!(
                "{} tensors stored, metadata lists {}",
                tensors.len(),
                envelope.tensors.len()
            ),
        ));
    }
    for (name, info) in &envelope.tensors {
        match tensors.get(name) {
            Some(t) if t.dims() == info.shape.as_slice() && dtype_name(t) == info.dtype => {}
            Some(t) => {
                return Err(corrupt(
                    &weights_path,
                    format!(
                        "tensor `{name}` is {:?} {} but metadata says {:?} {}",
                        t.dims(),
                        dtype_name(t),
                        info.shape,
                        info.dtype
                    ),
                ))
            }
            None => {
                return Err(CheckpointError::MissingTensor {
                    path: weights_path,
                    name: name.clone(),
                })
            }
        }
    }
    Ok(Loaded {
        paths,
        payload,
        tensors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Payload {
        iteration: u64,
        stats: Vec<f64>,
    }

    fn scratch_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("lhm-nets-ckpt-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn sample_tensors() -> Vec<(String, Tensor)> {
        let w = Tensor::new(&[[1.0f32, 2.0], [3.0, 4.0], [5.0, 6.0]], &Device::Cpu).unwrap();
        vec![("net.layers.0.weight".to_owned(), w)]
    }

    #[test]
    fn round_trip_and_every_kind_of_damage_is_a_typed_error() {
        let dir = scratch_dir("damage");
        let stem = dir.join("ckpt.v1");
        let payload = Payload {
            iteration: 7,
            stats: vec![0.1, 1.0 / 3.0],
        };
        save(&stem, "test", &sample_tensors(), &payload).unwrap();
        let loaded = load::<Payload>(&stem, "test").unwrap();
        assert_eq!(loaded.payload, payload);
        assert_eq!(
            loaded.f32_values("net.layers.0.weight", &[3, 2]).unwrap()[5],
            6.0
        );
        assert!(matches!(
            loaded.tensor("net.layers.0.weight", &[2, 3]),
            Err(CheckpointError::Shape { .. })
        ));
        assert!(matches!(
            loaded.tensor("nope", &[1]),
            Err(CheckpointError::MissingTensor { .. })
        ));
        assert!(matches!(
            load::<Payload>(&stem, "other"),
            Err(CheckpointError::Kind { .. })
        ));
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct OtherPayload {
            learning_rate: f64,
        }
        assert!(matches!(
            load::<OtherPayload>(&stem, "test"),
            Err(CheckpointError::Mismatch { .. })
        ));

        let paths = CheckpointPaths::new(&stem);
        let good = fs::read(&paths.weights).unwrap();
        // One flipped byte in the tensor data.
        let mut flipped = good.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 0x40;
        fs::write(&paths.weights, &flipped).unwrap();
        let err = load::<Payload>(&stem, "test").unwrap_err();
        assert!(matches!(err, CheckpointError::Checksum { .. }), "{err}");
        assert!(err.to_string().contains("ckpt.v1.safetensors"), "{err}");
        // Truncation.
        fs::write(&paths.weights, &good[..good.len() / 2]).unwrap();
        let err = load::<Payload>(&stem, "test").unwrap_err();
        assert!(
            matches!(err, CheckpointError::Corrupt { .. }) && err.to_string().contains("truncated"),
            "{err}"
        );
        // Missing file.
        fs::remove_file(&paths.weights).unwrap();
        assert!(matches!(
            load::<Payload>(&stem, "test"),
            Err(CheckpointError::Io { .. })
        ));
        fs::write(&paths.weights, &good).unwrap();
        // Garbage and other versions in the metadata.
        let meta = fs::read_to_string(&paths.meta).unwrap();
        fs::write(&paths.meta, &meta[..meta.len() / 2]).unwrap();
        assert!(matches!(
            load::<Payload>(&stem, "test"),
            Err(CheckpointError::Corrupt { .. })
        ));
        fs::write(
            &paths.meta,
            meta.replace("\"format_version\": 1", "\"format_version\": 99"),
        )
        .unwrap();
        let err = load::<Payload>(&stem, "test").unwrap_err();
        assert!(
            matches!(err, CheckpointError::Version { found: 99, .. }),
            "{err}"
        );
        fs::write(&paths.meta, &meta).unwrap();
        assert!(load::<Payload>(&stem, "test").is_ok());
        // No temporary files are left behind.
        let leftovers: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(leftovers.is_empty());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn load_into_rejects_wrong_shapes() {
        let dir = scratch_dir("shapes");
        let stem = dir.join("c");
        save(
            &stem,
            "test",
            &sample_tensors(),
            &Payload {
                iteration: 0,
                stats: vec![],
            },
        )
        .unwrap();
        let loaded = load::<Payload>(&stem, "test").unwrap();
        let wrong = Var::zeros((2, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
        let err = loaded
            .load_into(&[("net.layers.0.weight".to_owned(), wrong)])
            .unwrap_err();
        assert!(err.to_string().contains("[3, 2]"), "{err}");
        let right = Var::zeros((3, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
        loaded
            .load_into(&[("net.layers.0.weight".to_owned(), right.clone())])
            .unwrap();
        assert_eq!(
            right.as_tensor().to_vec2::<f32>().unwrap()[2],
            vec![5.0, 6.0]
        );
        let _ = fs::remove_dir_all(&dir);
    }
}
