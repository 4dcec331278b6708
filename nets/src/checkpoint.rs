//! Checkpoint files: `<stem>.json` is the manifest (format version, kind, the name of the tensor
//! file, its FNV-1a 64 checksum and tensor list, and a typed payload: configs, counters,
//! normaliser statistics, optimiser step counts, RNG states); the tensors are in
//! `<stem>.<checksum>.safetensors`, the file the manifest's `weights_file` names.
//!
//! Tensor names are plain dotted PyTorch-style names (`policy.mean.layers.0.weight`, weights
//! [out, in]), so a PyTorch user can read the weights with
//! `safetensors.torch.load_file(dir / json.load(open("<stem>.json"))["weights_file"])` and load
//! them into an `nn.Linear` stack.
//!
//! A save is atomic as a whole. The tensor file gets a name of its own (by checksum), so writing
//! it never touches the file the current manifest names; the manifest is then replaced by one
//! rename, the single commit point. A process killed at any moment leaves either the old
//! checkpoint or the new one, both complete (both files are written to a temporary file,
//! fsynced, renamed, and the directory fsynced). After the commit, tensor files no manifest
//! needs any more are deleted, except the previous one (a reader that read the old manifest
//! just before the commit can still open its tensors), and so are temporary files a killed save
//! left behind. (Checkpoints of format 1 written before this layout named their tensors
//! `<stem>.safetensors`; they still load.)

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
/// `weights` is the tensor file the manifest names once it has been read or written; before
/// that, the pre-manifest layout's `<stem>.safetensors`.
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

    /// The directory both files live in.
    fn dir(&self) -> PathBuf {
        parent_dir(&self.meta)
    }
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    }
}

fn file_name_of(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The tensor file of a save whose bytes have checksum `fnv` (16 hex digits).
fn weights_name(stem_name: &str, fnv: &str) -> String {
    format!("{stem_name}.{fnv}.safetensors")
}

/// Whether `name` is one of the files that only this stem's saves write: a tensor file
/// (`<stem>.<16 hex>.safetensors`, or the earlier layout's `<stem>.safetensors`) or a save's
/// temporary file (`.<that name or stem.json>.tmp-<pid>`). Another stem that merely shares the
/// prefix (`checkpoint.v1` beside `checkpoint`) never matches.
fn is_own_file(stem_name: &str, name: &str) -> bool {
    fn is_hex16(s: &str) -> bool {
        s.len() == 16 && s.bytes().all(|b| b.is_ascii_hexdigit())
    }
    let tensors = |rest: &str| {
        rest == "safetensors" || rest.strip_suffix(".safetensors").is_some_and(is_hex16)
    };
    if let Some(rest) = name
        .strip_prefix(stem_name)
        .and_then(|r| r.strip_prefix('.'))
    {
        return tensors(rest);
    }
    let Some((file, pid)) = name
        .strip_prefix('.')
        .and_then(|r| r.strip_prefix(stem_name))
        .and_then(|r| r.strip_prefix('.'))
        .and_then(|r| r.rsplit_once(".tmp-"))
    else {
        return false;
    };
    !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()) && (file == "json" || tensors(file))
}

/// Test hook for killing a process at a given point of a save: with
/// `LHM_CHECKPOINT_FAULT=<point>:<n>`, the n-th time (from 1) this process reaches `<point>` it
/// aborts on the spot, as a SIGKILL would stop it. Points, in order: `weights-written` (the
/// tensors' temporary file is complete), `weights-renamed`, `meta-written`, `meta-renamed` (the
/// commit, before the clean-up).
fn fault_point(point: &str) {
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::OnceLock;
    static FAULT: OnceLock<Option<(String, u64)>> = OnceLock::new();
    static SEEN: AtomicU64 = AtomicU64::new(0);
    let fault = FAULT.get_or_init(|| {
        let spec = std::env::var("LHM_CHECKPOINT_FAULT").ok()?;
        let (name, n) = spec.rsplit_once(':')?;
        Some((name.to_owned(), n.parse().ok()?))
    });
    if let Some((name, n)) = fault {
        if name == point && SEEN.fetch_add(1, Ordering::SeqCst) + 1 == *n {
            eprintln!("LHM_CHECKPOINT_FAULT: aborting at {point}");
            std::process::abort();
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

/// Writes `bytes` to `path` through a temporary file (`.<name>.tmp-<pid>`, removed on failure)
/// and syncs the file and the rename; `point` names the fault-injection points (`<point>-written`
/// before the rename, `<point>-renamed` after it). Also the DAgger dataset's writer.
pub fn write_atomic(path: &Path, bytes: &[u8], point: &str) -> CheckpointResult<()> {
    let io = |action: &'static str| {
        move |source| CheckpointError::Io {
            path: path.to_owned(),
            action,
            source,
        }
    };
    let dir = parent_dir(path);
    let file_name = file_name_of(path);
    let tmp = dir.join(format!(".{file_name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut file = File::create(&tmp).map_err(io("creating a temporary file"))?;
        file.write_all(bytes).map_err(io("writing"))?;
        file.sync_all().map_err(io("syncing"))?;
        fault_point(&format!("{point}-written"));
        fs::rename(&tmp, path).map_err(io("renaming the temporary file into place"))?;
        // Make the rename itself durable.
        File::open(&dir)
            .and_then(|d| d.sync_all())
            .map_err(io("syncing the directory"))?;
        fault_point(&format!("{point}-renamed"));
        Ok(())
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
    let mut paths = CheckpointPaths::new(stem);
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
    let stem_name = file_name_of(stem);
    let fnv = format!("{:016x}", fnv1a64(&bytes));
    let weights_file = weights_name(&stem_name, &fnv);
    paths.weights = paths.dir().join(&weights_file);
    // The tensor file the manifest names now: kept through the clean-up below.
    let previous = read_weights_file(&paths.meta);
    let envelope = Envelope {
        format: FORMAT_NAME.to_owned(),
        format_version: FORMAT_VERSION,
        kind: kind.to_owned(),
        weights_file: weights_file.clone(),
        weights_len: bytes.len() as u64,
        weights_fnv1a64: fnv,
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
    write_atomic(&paths.weights, &bytes, "weights")?;
    write_atomic(&paths.meta, &json, "meta")?;
    remove_unneeded(&paths.dir(), &stem_name, &[Some(weights_file), previous]);
    Ok(())
}

/// A checkpoint path as users write it, with or without `.json` / `.safetensors`, as its stem.
pub fn stem_of(path: &Path) -> PathBuf {
    match path.extension().and_then(|e| e.to_str()) {
        Some("json" | "safetensors") => path.with_extension(""),
        _ => path.to_owned(),
    }
}

/// The tensor file the checkpoint at `stem` has committed to, as its manifest names it.
pub fn committed_weights(stem: &Path) -> CheckpointResult<PathBuf> {
    let paths = CheckpointPaths::new(stem);
    let name = read_weights_file(&paths.meta).ok_or_else(|| CheckpointError::Corrupt {
        path: paths.meta.clone(),
        reason: "no readable manifest naming a weights_file".into(),
    })?;
    Ok(paths.dir().join(name))
}

/// The `weights_file` a manifest names, if it can be read (a plain file name only).
fn read_weights_file(meta: &Path) -> Option<String> {
    #[derive(Deserialize)]
    struct Head {
        weights_file: String,
    }
    let head: Head = serde_json::from_slice(&fs::read(meta).ok()?).ok()?;
    plain_file_name(&head.weights_file).then_some(head.weights_file)
}

fn plain_file_name(name: &str) -> bool {
    !name.is_empty() && name != "." && name != ".." && !name.contains(['/', '\\'])
}

/// Deletes this stem's tensor files other than `keep` and its save's temporary files. Best
/// effort: what cannot be deleted now is deleted by the next save.
fn remove_unneeded(dir: &Path, stem_name: &str, keep: &[Option<String>]) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if keep.iter().flatten().any(|k| *k == name) {
            continue;
        }
        if is_own_file(stem_name, &name) {
            let _ = fs::remove_file(entry.path());
        }
    }
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
    let mut paths = CheckpointPaths::new(stem);
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

    if !plain_file_name(&envelope.weights_file) {
        return Err(corrupt(
            &meta_path,
            format!(
                "weights_file `{}` is not a file name in the checkpoint's directory",
                envelope.weights_file
            ),
        ));
    }
    paths.weights = paths.dir().join(&envelope.weights_file);
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

        let paths = loaded.paths.clone();
        let weights_name = file_name_of(&paths.weights);
        assert!(
            weights_name.starts_with("ckpt.v1.") && weights_name.ends_with(".safetensors"),
            "{weights_name}"
        );
        let good = fs::read(&paths.weights).unwrap();
        // One flipped byte in the tensor data.
        let mut flipped = good.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 0x40;
        fs::write(&paths.weights, &flipped).unwrap();
        let err = load::<Payload>(&stem, "test").unwrap_err();
        assert!(matches!(err, CheckpointError::Checksum { .. }), "{err}");
        assert!(err.to_string().contains(&weights_name), "{err}");
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
    fn own_files_are_told_apart_from_other_stems() {
        for own in [
            "checkpoint.0123456789abcdef.safetensors",
            "checkpoint.safetensors",
            ".checkpoint.json.tmp-42",
            ".checkpoint.0123456789abcdef.safetensors.tmp-7",
            ".checkpoint.safetensors.tmp-7",
        ] {
            assert!(is_own_file("checkpoint", own), "{own}");
        }
        for other in [
            "checkpoint.json",
            "checkpoint.v1.0123456789abcdef.safetensors",
            "checkpoint.v1.safetensors",
            ".checkpoint.v1.json.tmp-42",
            "checkpoint.0123.safetensors",
            ".checkpoint.json.tmp-",
            ".checkpoint.json.tmp-x1",
            "policy.0123456789abcdef.safetensors",
            "metrics.csv",
        ] {
            assert!(!is_own_file("checkpoint", other), "{other}");
        }
    }

    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_save_keeps_the_new_and_the_previous_tensors_and_clears_what_a_killed_save_left() {
        let dir = scratch_dir("generations");
        let stem = dir.join("c");
        let tensors = |v: f32| {
            vec![(
                "w".to_owned(),
                Tensor::new(&[v, v + 1.0], &Device::Cpu).unwrap(),
            )]
        };
        let payload = |iteration| Payload {
            iteration,
            stats: vec![],
        };
        // Another stem with a shared prefix, and what a save killed mid-way leaves behind.
        save(&dir.join("c.v1"), "test", &tensors(9.0), &payload(9)).unwrap();
        fs::write(dir.join(".c.json.tmp-999999"), b"half a manifest").unwrap();
        fs::write(
            dir.join(".c.00000000000000ff.safetensors.tmp-999999"),
            b"half",
        )
        .unwrap();
        fs::write(dir.join("c.safetensors"), b"an earlier layout's tensors").unwrap();
        let mut committed = Vec::new();
        for i in 0..3u64 {
            save(&stem, "test", &tensors(i as f32), &payload(i)).unwrap();
            let loaded = load::<Payload>(&stem, "test").unwrap();
            assert_eq!(loaded.payload.iteration, i);
            committed.push(file_name_of(&loaded.paths.weights));
        }
        // The last two tensor files (the previous one for readers of the old manifest), the
        // other stem untouched, no temporary files and no orphaned tensors.
        let v1 = file_name_of(
            &load::<Payload>(&dir.join("c.v1"), "test")
                .unwrap()
                .paths
                .weights,
        );
        let mut expected = vec![
            "c.json".to_owned(),
            committed[1].clone(),
            committed[2].clone(),
            "c.v1.json".to_owned(),
            v1,
        ];
        expected.sort();
        assert_eq!(names_in(&dir), expected);
        // Saving the same tensors again rewrites the same file; the previous manifest named it
        // too, so the one before goes.
        save(&stem, "test", &tensors(2.0), &payload(2)).unwrap();
        expected.retain(|n| *n != committed[1]);
        assert_eq!(names_in(&dir), expected);
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_earlier_layouts_checkpoint_loads_and_a_manifest_cannot_point_outside_its_directory() {
        let dir = scratch_dir("layout");
        let stem = dir.join("old");
        save(
            &stem,
            "test",
            &sample_tensors(),
            &Payload {
                iteration: 3,
                stats: vec![],
            },
        )
        .unwrap();
        let loaded = load::<Payload>(&stem, "test").unwrap();
        let new_name = file_name_of(&loaded.paths.weights);
        fs::rename(&loaded.paths.weights, dir.join("old.safetensors")).unwrap();
        let meta = fs::read_to_string(&loaded.paths.meta).unwrap();
        fs::write(
            &loaded.paths.meta,
            meta.replace(&new_name, "old.safetensors"),
        )
        .unwrap();
        assert_eq!(load::<Payload>(&stem, "test").unwrap().payload.iteration, 3);
        for bad in ["../old.safetensors", "/etc/passwd", ""] {
            fs::write(&loaded.paths.meta, meta.replace(&new_name, bad)).unwrap();
            let err = load::<Payload>(&stem, "test").unwrap_err();
            assert!(
                matches!(err, CheckpointError::Corrupt { .. })
                    && err.to_string().contains("weights_file"),
                "{bad}: {err}"
            );
        }
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
