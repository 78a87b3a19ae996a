//! The summary section: topics and message counts without reading the
//! data section, trusted only when its CRC and records check out.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use ::mcap::records::{op, Record};
use ::mcap::{parse_record, MAGIC};

use super::{split_records, topic_list, RECORD_PREFIX};
use crate::{normalize_type, TopicInfo};
use edtmap_io::IoError;

/// Largest summary section read, bytes: a bigger one is skipped for a scan.
const MAX_SUMMARY_BYTES: u64 = 1 << 28;
/// The footer record: prefix, summary start, summary offset start, CRC.
const FOOTER_BYTES: usize = RECORD_PREFIX + 8 + 8 + 4;

/// Topics from the summary section, or `None` when the file has none or one
/// that fails its checks (footer, CRC, records, statistics).
pub(super) fn summary_topics(file: &mut File, path: &Path) -> Result<Option<Vec<TopicInfo>>, IoError> {
    let io = |e| IoError::io(path, e);
    let len = file.metadata().map_err(io)?.len();
    let tail_len = (FOOTER_BYTES + MAGIC.len()) as u64;
    let Some(footer_at) = len.checked_sub(tail_len).filter(|&at| at >= MAGIC.len() as u64) else {
        return Ok(None);
    };
    let mut tail = [0; FOOTER_BYTES + 8];
    file.seek(SeekFrom::Start(footer_at)).map_err(io)?;
    file.read_exact(&mut tail).map_err(io)?;
    let (footer, magic) = tail.split_at(FOOTER_BYTES);
    if *magic != *MAGIC || footer[0] != op::FOOTER || footer[1..RECORD_PREFIX] != 20u64.to_le_bytes() {
        return Ok(None);
    }
    let Ok(Record::Footer(footer_record)) = parse_record(op::FOOTER, &footer[RECORD_PREFIX..]) else {
        return Ok(None);
    };
    let start = footer_record.summary_start;
    if start < MAGIC.len() as u64 || start > footer_at || footer_at - start > MAX_SUMMARY_BYTES {
        return Ok(None);
    }
    let mut section = vec![0; (footer_at - start) as usize];
    file.seek(SeekFrom::Start(start)).map_err(io)?;
    file.read_exact(&mut section).map_err(io)?;
    if footer_record.summary_crc != 0 {
        // The CRC covers the section and the footer up to the CRC field.
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&section);
        hasher.update(&footer[..FOOTER_BYTES - 4]);
        if hasher.finalize() != footer_record.summary_crc {
            tracing::debug!("{}: the summary CRC does not match; scanning for the topics", path.display());
            return Ok(None);
        }
    }
    Ok(parse_summary(&section))
}

/// Topics from the summary section's schema, channel and statistics
/// records; `None` when one is malformed, the statistics are missing or do
/// not count the channels listed.
fn parse_summary(section: &[u8]) -> Option<Vec<TopicInfo>> {
    let mut schemas = HashMap::new();
    let mut channels = BTreeMap::new();
    let mut statistics = None;
    for record in split_records(section) {
        let (_, opcode, body) = record.ok()?;
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::STATISTICS) {
            continue;
        }
        match parse_record(opcode, body).ok()? {
            Record::Schema { header, .. } if header.id != 0 => {
                schemas.insert(header.id, normalize_type(&header.name));
            }
            Record::Channel(channel) => {
                channels.insert(channel.id, channel);
            }
            Record::Statistics(stats) => statistics = Some(stats),
            _ => {}
        }
    }
    let statistics = statistics?;
    if u32::try_from(channels.len()).ok()? != statistics.channel_count {
        return None;
    }
    // The spec: an empty map means the counts were not recorded; scan.
    if statistics.channel_message_counts.is_empty() && statistics.message_count > 0 {
        return None;
    }
    let counts = channels.into_values().map(|c| {
        let messages = statistics.channel_message_counts.get(&c.id).copied().unwrap_or(0);
        (c.topic, schemas.get(&c.schema_id).cloned().unwrap_or_default(), messages)
    });
    Some(topic_list(counts))
}
