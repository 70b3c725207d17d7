//! One MCAP file being written: its schemas and channels (added on first
//! use), the MECH metadata record that begins it, chunks closed every
//! second so a crash loses at most the last one, and the summary (the index
//! Foxglove and Lichtblick seek with) written when it is finished.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};

use super::RecordError;
use super::schema;

/// Name of the metadata record at the start of every recording.
pub const METADATA: &str = "mech";
/// Name of the metadata record written when a file is finished.
pub const METADATA_END: &str = "mech.end";
/// The MCAP profile of MECH recordings.
pub const PROFILE: &str = "mech";

/// An open recording file.
pub(super) struct McapFile {
    mcap: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    schemas: HashMap<&'static str, u16>,
    channels: HashMap<String, u16>,
    /// Next sequence number of each channel.
    sequences: HashMap<u16, u32>,
}

impl std::fmt::Debug for McapFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("path", &self.path)
            .finish()
    }
}

impl McapFile {
    /// Creates `path` (and its directory) and writes the metadata record.
    /// `fresh`: the file must not exist yet (created exclusively, so
    /// nothing already there, a symbolic link included, is truncated or
    /// followed); otherwise an existing file is replaced.
    pub(super) fn create(
        path: &Path,
        fresh: bool,
        compress: bool,
        metadata: BTreeMap<String, String>,
    ) -> Result<McapFile, RecordError> {
        let created = |source| RecordError::Create {
            path: path.to_owned(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(created)?;
        }
        let file = if fresh {
            File::create_new(path)
        } else {
            File::create(path)
        }
        .map_err(created)?;
        let compression = compress.then_some(mcap::Compression::Zstd);
        let options = mcap::WriteOptions::new()
            .profile(PROFILE)
            .compression(compression)
            .compression_level(1)
            .compression_threads(0);
        let mut mcap = options
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(|e| write_error(path, e))?;
        let name = METADATA.to_string();
        mcap.write_metadata(&Metadata { name, metadata })
            .map_err(|e| write_error(path, e))?;
        Ok(McapFile {
            mcap,
            path: path.to_owned(),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            sequences: HashMap::new(),
        })
    }

    /// The id of the channel on `topic`, added on first use with the
    /// schema named `schema` (JSON Schema, JSON messages) or none (raw).
    pub(super) fn channel(
        &mut self,
        topic: &str,
        schema: Option<&'static str>,
    ) -> Result<u16, RecordError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let (schema_id, encoding) = match schema {
            Some(name) => (self.schema(name)?, "json"),
            None => (0, schema::RAW_ENCODING),
        };
        let id = self
            .mcap
            .add_channel(schema_id, topic, encoding, &BTreeMap::new())
            .map_err(|e| write_error(&self.path, e))?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    fn schema(&mut self, name: &'static str) -> Result<u16, RecordError> {
        if let Some(&id) = self.schemas.get(name) {
            return Ok(id);
        }
        let data = serde_json::to_vec(&schema::schema(name)).unwrap_or_default();
        let id = self
            .mcap
            .add_schema(name, "jsonschema", &data)
            .map_err(|e| write_error(&self.path, e))?;
        self.schemas.insert(name, id);
        Ok(id)
    }

    /// Writes one message; `sequence` numbers it (the channel's own count
    /// when `None`).
    pub(super) fn write(
        &mut self,
        channel: u16,
        sequence: Option<u32>,
        log_ns: u64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        let next = self.sequences.entry(channel).or_insert(0);
        *next = next.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel,
            sequence: sequence.unwrap_or(*next),
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| write_error(&self.path, e))
    }

    /// Closes the current chunk and writes it out; returns the file's size.
    pub(super) fn flush(&mut self) -> Result<u64, RecordError> {
        self.mcap.flush().map_err(|e| write_error(&self.path, e))?;
        std::fs::metadata(&self.path)
            .map(|m| m.len())
            .map_err(|e| write_error(&self.path, e))
    }

    /// Writes `end` as the closing metadata record, then the summary.
    pub(super) fn finish(mut self, end: BTreeMap<String, String>) -> Result<(), RecordError> {
        let name = METADATA_END.to_string();
        let path = self.path.clone();
        self.mcap
            .write_metadata(&Metadata {
                name,
                metadata: end,
            })
            .map_err(|e| write_error(&path, e))?;
        self.mcap.finish().map_err(|e| write_error(&path, e))?;
        let mut out = self.mcap.into_inner();
        std::io::Write::flush(&mut out).map_err(|e| write_error(&path, e))
    }
}

fn write_error(path: &Path, e: impl std::fmt::Display) -> RecordError {
    RecordError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}
