//! `lhm recover`: a recording cut short (SIGKILL, power loss) has no summary and no end magic, so
//! the standard readers refuse it. Every complete record before the cut is still there; this
//! copies them, in order, into a new, properly finished file.

use std::collections::HashSet;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::read::{ChunkFlattener, Options};
use mcap::records::Record;
use mcap::{Attachment, WriteOptions, Writer};

use crate::RecordError;

/// What a recovery kept.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct RecoverReport {
    pub schemas: u64,
    pub channels: u64,
    pub messages: u64,
    pub metadata: u64,
    pub attachments: u64,
    /// The input ended properly (its data-end record was reached): nothing was lost.
    pub complete: bool,
    /// Why reading stopped early (the damage), when it did.
    pub stopped_by: Option<String>,
}

/// Copies every complete schema, channel, message, metadata and attachment record of `input`
/// into a new MCAP file at `output` (written beside it and renamed into place, so a failed
/// recovery leaves no half file). `input` is only read.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, RecordError> {
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    };
    if same(input, output) {
        return Err(RecordError::Recover {
            path: output.to_path_buf(),
            reason: "the output must not be the input".into(),
        });
    }
    let bytes = std::fs::read(input).map_err(|source| RecordError::Read {
        path: input.to_path_buf(),
        source,
    })?;
    let tmp = tmp_path(output);
    let file = File::create(&tmp).map_err(|source| RecordError::Create {
        path: tmp.clone(),
        source,
    })?;
    // Whatever goes wrong from here on, no half-written temporary is left behind.
    let report = match write_recovered(&bytes, input, output, &tmp, file) {
        Ok(r) => r,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
    };
    std::fs::rename(&tmp, output).map_err(|source| RecordError::Close {
        path: output.to_path_buf(),
        source,
    })?;
    Ok(report)
}

/// Copies the complete records of `bytes` (the file `input`) into `file` (the temporary `tmp`
/// that becomes `output`), finished and synced.
fn write_recovered(
    bytes: &[u8],
    input: &Path,
    output: &Path,
    tmp: &Path,
    file: File,
) -> Result<RecoverReport, RecordError> {
    let mcap_err = |source| RecordError::Mcap {
        path: output.to_path_buf(),
        source,
    };
    let options = WriteOptions::new()
        .compression(Some(mcap::Compression::Lz4))
        .chunk_size(Some(crate::CHUNK_SIZE))
        .library(concat!("lhm-record recover ", env!("CARGO_PKG_VERSION")));
    let mut writer = Writer::with_options(BufWriter::new(file), options).map_err(mcap_err)?;
    let mut report = RecoverReport::default();
    let mut schemas = HashSet::new();
    let mut channels = HashSet::new();
    let records =
        ChunkFlattener::new_with_options(bytes, Options::IgnoreEndMagic.into()).map_err(|e| {
            RecordError::Recover {
                path: input.to_path_buf(),
                reason: format!("not an MCAP file: {e}"),
            }
        })?;
    for (i, record) in records.enumerate() {
        let record = match record {
            Ok(r) => r,
            Err(e) if i == 0 => {
                drop(writer);
                return Err(RecordError::Recover {
                    path: input.to_path_buf(),
                    reason: format!("not an MCAP file: {e}"),
                });
            }
            Err(e) => {
                report.stopped_by = Some(e.to_string());
                break;
            }
        };
        match record {
            // Writers repeat schema and channel records (in chunks and the summary): keep the
            // first of each id.
            Record::Schema { header, data } if schemas.insert(header.id) => {
                writer
                    .add_schema_with_id(header.id, &header.name, &header.encoding, &data)
                    .map_err(mcap_err)?;
                report.schemas += 1;
            }
            Record::Channel(c) if channels.insert(c.id) => {
                writer
                    .add_channel_with_id(
                        c.id,
                        c.schema_id,
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )
                    .map_err(mcap_err)?;
                report.channels += 1;
            }
            Record::Message { header, data } => {
                writer
                    .write_to_known_channel(&header, &data)
                    .map_err(mcap_err)?;
                report.messages += 1;
            }
            Record::Metadata(m) => {
                writer.write_metadata(&m).map_err(mcap_err)?;
                report.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                writer
                    .attach(&Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data,
                    })
                    .map_err(mcap_err)?;
                report.attachments += 1;
            }
            Record::DataEnd(_) => {
                report.complete = true;
                break;
            }
            _ => {}
        }
    }
    writer.finish().map_err(mcap_err)?;
    let file = writer
        .into_inner()
        .into_inner()
        .map_err(|e| RecordError::Close {
            path: tmp.to_path_buf(),
            source: e.into_error(),
        })?;
    file.sync_all().map_err(|source| RecordError::Close {
        path: tmp.to_path_buf(),
        source,
    })?;
    Ok(report)
}

fn tmp_path(output: &Path) -> PathBuf {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "recovered.mcap".into());
    output.with_file_name(format!(".tmp-{name}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::McapRecorder;
    use lhm_protos::{Metrics, WireMessage};

    fn metrics(i: u64) -> Metrics {
        Metrics {
            run_id: "r".into(),
            process: "learner".into(),
            unix_time_ms: 1_000 + i,
            iteration: i,
            ..Metrics::versioned()
        }
    }

    /// A recording cut at every byte after its first flushed chunk recovers into a file the
    /// strict reader accepts, holding every message flushed before the cut.
    #[test]
    fn a_file_cut_anywhere_recovers_what_was_flushed() {
        let dir = std::env::temp_dir().join(format!("lhm-recover-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let full = dir.join("full.mcap");
        let mut rec = McapRecorder::create(&full).unwrap();
        // Each metrics write ends its chunk; remember the file size after each.
        let mut sizes = Vec::new();
        for i in 0..6 {
            rec.write_metrics(&metrics(i)).unwrap();
            sizes.push(std::fs::metadata(&full).unwrap().len());
        }
        rec.finish().unwrap();
        let bytes = std::fs::read(&full).unwrap();
        let cut = dir.join("cut.mcap");
        let out = dir.join("out.mcap");
        let step = (bytes.len() / 97).max(1);
        for len in (sizes[0] as usize..bytes.len()).step_by(step) {
            std::fs::write(&cut, &bytes[..len]).unwrap();
            assert!(
                mcap::MessageStream::new(&bytes[..len]).is_err()
                    || mcap::MessageStream::new(&bytes[..len])
                        .unwrap()
                        .any(|m| m.is_err()),
                "a file cut at {len} bytes reads as whole"
            );
            let report = recover(&cut, &out).unwrap();
            let flushed = sizes.iter().filter(|&&s| s as usize <= len).count() as u64;
            assert!(
                report.messages >= flushed,
                "cut at {len}: {} messages recovered, {flushed} were flushed",
                report.messages
            );
            let fixed = std::fs::read(&out).unwrap();
            // The strict reader (end magic and summary required) reads it all.
            let n = mcap::MessageStream::new(&fixed)
                .unwrap()
                .collect::<Result<Vec<_>, _>>()
                .unwrap()
                .len() as u64;
            assert_eq!(n, report.messages);
            assert!(mcap::Summary::read(&fixed).unwrap().is_some());
        }
        // A whole file recovers completely.
        let report = recover(&full, &out).unwrap();
        assert!(report.complete, "{report:?}");
        assert_eq!(report.messages, 6);
        // Not onto itself, and not from garbage.
        assert!(recover(&full, &full).is_err());
        std::fs::write(&cut, b"not an mcap file at all").unwrap();
        let err = recover(&cut, &out).unwrap_err().to_string();
        assert!(err.contains("cut.mcap"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
