//! The MCAP side of a replay: scanning the file's records (stopping at the
//! first that cannot be read), and decoding a chunk's messages into
//! [`Entry`]s by what their topic carries.

use std::collections::{BTreeMap, HashMap};
use std::time::Duration;

use mcap::read::{LinearReader, Options};
use mcap::records::{ChunkHeader, Record};
use serde::Deserialize;

use super::Entry;
use crate::event::{Event, Stamped};
use crate::record::{METADATA, METADATA_END, PROFILE, schema};
use crate::router::OperatorRecord;

/// One chunk of the file, still compressed.
#[derive(Debug)]
pub(super) struct Chunk {
    header: ChunkHeader,
    data: Vec<u8>,
}

/// What a channel carries, by its topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Kind {
    Events,
    Snapshot,
    Telemetry(String),
    Operator,
    Clusters,
    /// Raw bytes, decisions, poses, the scene, the log: for Foxglove and
    /// other readers; a replay rebuilds them from the rest.
    Other,
}

impl Kind {
    fn of(topic: &str) -> Kind {
        match topic {
            schema::EVENTS => Kind::Events,
            schema::SNAPSHOT => Kind::Snapshot,
            schema::OPERATOR => Kind::Operator,
            schema::CLUSTERS => Kind::Clusters,
            t => match schema::telemetry_robot(t) {
                Some(robot) => Kind::Telemetry(robot.to_string()),
                None => Kind::Other,
            },
        }
    }
}

/// The largest chunk a replay decompresses, bytes. The recorder closes its
/// chunks at the MCAP writer's default size (768 KiB) or every second; a
/// damaged header could otherwise ask for any amount of memory.
const MAX_CHUNK: u64 = 64 << 20;

/// Channel id -> topic and what it carries.
pub(super) type Channels = HashMap<u16, (String, Kind)>;

/// The file's records, up to the first that cannot be read.
#[derive(Debug)]
pub(super) struct Scanned {
    pub(super) chunks: Vec<Chunk>,
    pub(super) router_start_ns: u64,
    pub(super) damage: Option<String>,
    pub(super) end: Option<BTreeMap<String, String>>,
}

/// Reads the file's records in order. An error before the MECH header and
/// metadata is fatal; after them it is damage, and what came before it
/// stands.
pub(super) fn scan(bytes: &[u8]) -> Result<Scanned, String> {
    let reader = LinearReader::new_with_options(bytes, Options::IgnoreEndMagic.into())
        .map_err(|e| e.to_string())?;
    let mut out = Scanned {
        chunks: Vec::new(),
        router_start_ns: 0,
        damage: None,
        end: None,
    };
    let (mut header, mut metadata, mut data_end) = (false, false, false);
    for record in reader {
        match record {
            Ok(Record::Header(h)) if h.profile != PROFILE => {
                return Err(format!(
                    "its MCAP profile is {:?}, not {PROFILE:?}",
                    h.profile
                ));
            }
            Ok(Record::Header(_)) => header = true,
            Ok(Record::Metadata(m)) if m.name == METADATA => {
                out.router_start_ns = start_ns(&m.metadata)?;
                metadata = true;
            }
            Ok(Record::Metadata(m)) if m.name == METADATA_END => out.end = Some(m.metadata),
            Ok(Record::Chunk { header, .. }) if header.uncompressed_size > MAX_CHUNK => {
                let what = format!(
                    "a chunk that claims {} bytes uncompressed (a recording's are under {MAX_CHUNK})",
                    header.uncompressed_size
                );
                out.damage = Some(damage(&what, out.chunks.len()));
                break;
            }
            Ok(Record::Chunk { header, data }) => out.chunks.push(Chunk {
                header,
                data: data.into_owned(),
            }),
            Ok(Record::DataEnd(_)) => {
                data_end = true;
                break;
            }
            Ok(_) => {}
            Err(e) if !(header && metadata) => return Err(e.to_string()),
            Err(e) => {
                out.damage = Some(damage(&e.to_string(), out.chunks.len()));
                break;
            }
        }
    }
    if !(header && metadata) {
        return Err("no MECH metadata record at its start".into());
    }
    if !data_end && out.damage.is_none() {
        out.damage = Some(damage("the file ends early", out.chunks.len()));
    }
    Ok(out)
}

fn damage(what: &str, chunks: usize) -> String {
    format!(
        "{what} (truncated or corrupt) after {chunks} complete chunks; the recorder did not finish it or it was damaged since"
    )
}

fn start_ns(meta: &BTreeMap<String, String>) -> Result<u64, String> {
    meta.get("router_start_unix_ns")
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| "its metadata has no router_start_unix_ns".to_string())
}

/// Router time from the first to the last chunk, from the chunks' headers.
pub(super) fn span(chunks: &[Chunk], start_ns: u64) -> Duration {
    let first = chunks.iter().map(|c| c.header.message_start_time).min();
    let last = chunks.iter().map(|c| c.header.message_end_time).max();
    match (first, last) {
        (Some(a), Some(b)) => Duration::from_nanos(b.saturating_sub(a.max(start_ns))),
        _ => Duration::ZERO,
    }
}

/// Decodes a chunk for the first time: learns its channels, counts its
/// messages by topic and checks that every one decodes.
pub(super) fn chunk(
    c: &Chunk,
    channels: &mut Channels,
    start_ns: u64,
    counts: &mut BTreeMap<String, u64>,
) -> Result<Vec<Entry>, String> {
    let mut out = Vec::new();
    let bytes = uncompressed(c)?;
    for record in LinearReader::sans_magic(&bytes) {
        match record.map_err(|e| e.to_string())? {
            Record::Channel(ch) => {
                let kind = Kind::of(&ch.topic);
                channels.insert(ch.id, (ch.topic, kind));
            }
            Record::Message { header, data } => {
                let Some((topic, kind)) = channels.get(&header.channel_id) else {
                    return Err(format!(
                        "a message on unknown channel {}",
                        header.channel_id
                    ));
                };
                *counts.entry(topic.clone()).or_default() += 1;
                let at = Duration::from_nanos(header.log_time.saturating_sub(start_ns));
                if let Some(e) = entry(kind, at, &data).map_err(|e| format!("{topic}: {e}"))? {
                    out.push(e);
                }
            }
            _ => {}
        }
    }
    Ok(out)
}

/// A chunk's records, decompressed into no more than the size its header
/// states (at most [`MAX_CHUNK`]) and checked against its CRC; the MCAP
/// crate's chunk reader trusts the lengths inside the data, so a damaged
/// chunk could make it ask for any amount of memory.
fn uncompressed(c: &Chunk) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    let size = usize::try_from(c.header.uncompressed_size.min(MAX_CHUNK)).unwrap_or(0);
    let bytes = match c.header.compression.as_str() {
        "" => std::borrow::Cow::Borrowed(&c.data[..]),
        "zstd" => std::borrow::Cow::Owned(
            zstd::bulk::decompress(&c.data, size)
                .map_err(|e| format!("a chunk does not decompress: {e}"))?,
        ),
        other => {
            return Err(format!(
                "a chunk compressed with {other:?}, which MECH never writes"
            ));
        }
    };
    if bytes.len() as u64 != c.header.uncompressed_size {
        return Err("a chunk's size is not what its header says".into());
    }
    let crc = c.header.uncompressed_crc;
    if crc != 0 && crc32fast::hash(&bytes) != crc {
        return Err("a chunk fails its CRC".into());
    }
    Ok(bytes)
}

/// Decodes a chunk already checked by [`chunk`].
pub(super) fn entries(c: &Chunk, channels: &Channels, start_ns: u64) -> Vec<Entry> {
    let Ok(bytes) = uncompressed(c) else {
        return Vec::new();
    };
    LinearReader::sans_magic(&bytes)
        .filter_map(|r| match r.ok()? {
            Record::Message { header, data } => {
                let (_, kind) = channels.get(&header.channel_id)?;
                let at = Duration::from_nanos(header.log_time.saturating_sub(start_ns));
                entry(kind, at, &data).ok().flatten()
            }
            _ => None,
        })
        .collect()
}

#[derive(Deserialize)]
struct Operator {
    source: String,
    line: usize,
    text: String,
    ok: bool,
    summary: String,
    /// Lines after the summary (files from before they were recorded have
    /// none).
    #[serde(default)]
    details: Vec<String>,
}

#[derive(Deserialize)]
struct Clusters {
    clusters: BTreeMap<String, Vec<String>>,
}

/// The entry a message holds, if its topic carries one.
fn entry(kind: &Kind, at: Duration, data: &[u8]) -> Result<Option<Entry>, serde_json::Error> {
    Ok(Some(match kind {
        Kind::Events => Entry::Event(Stamped {
            at,
            event: serde_json::from_slice(data)?,
        }),
        Kind::Snapshot => Entry::Snapshot(Stamped {
            at,
            event: serde_json::from_slice(data)?,
        }),
        Kind::Telemetry(robot) => Entry::Event(Stamped {
            at,
            event: Event::Telemetry {
                robot: robot.clone(),
                telemetry: serde_json::from_slice(data)?,
            },
        }),
        Kind::Operator => {
            let o: Operator = serde_json::from_slice(data)?;
            Entry::Operator(OperatorRecord {
                at,
                source: o.source,
                line: o.line,
                text: o.text,
                ok: o.ok,
                summary: std::iter::once(o.summary)
                    .chain(o.details)
                    .collect::<Vec<_>>()
                    .join("\n"),
            })
        }
        Kind::Clusters => Entry::Clusters {
            at,
            clusters: serde_json::from_slice::<Clusters>(data)?.clusters,
        },
        Kind::Other => return Ok(None),
    }))
}
