//! Recordings written with `mcap::Writer`, read back whole, without a
//! summary, cut short, damaged and mutated.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use ::mcap::records::{op, MessageHeader};
use ::mcap::{Compression, WriteOptions, MAGIC};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::{split_records, summary_topics, topic_list, McapReader, RECORD_PREFIX};
use crate::{normalize_type, Encoding, RawMessage, TopicInfo};
use edtmap_io::IoError;

const TOPICS: [(&str, &str); 3] = [
    ("/velodyne_points", "sensor_msgs/msg/PointCloud2"),
    ("/tf", "tf2_msgs/msg/TFMessage"),
    ("/odom", "nav_msgs/msg/Odometry"),
];
const MESSAGES: usize = 48;
const PER_CHUNK: usize = 8;

/// The messages of the test recordings: the topics in turn, payloads of
/// varying length behind a CDR header.
fn expected() -> Vec<RawMessage> {
    (0..MESSAGES)
        .map(|i| {
            let (topic, msg_type) = TOPICS[i % TOPICS.len()];
            let mut data = vec![0, 1, 0, 0];
            data.extend((0..(i * 7) % 40 + 1).map(|k| (i * 3 + k) as u8));
            let (topic, msg_type) = (topic.to_string(), normalize_type(msg_type));
            RawMessage { topic, msg_type, log_time_ns: 1_000 + 10 * i as u64, data, encoding: Encoding::Cdr }
        })
        .collect()
}

fn expected_topics(messages: &[RawMessage]) -> Vec<TopicInfo> {
    topic_list(messages.iter().map(|m| (m.topic.clone(), m.msg_type.clone(), 1)))
}

/// A recording of `expected()`, a chunk per `PER_CHUNK` messages when
/// chunked.
fn recording(options: WriteOptions) -> Vec<u8> {
    let mut writer = options.chunk_size(None).create(Cursor::new(Vec::new())).expect("writer");
    let mut channels = Vec::new();
    for (topic, msg_type) in TOPICS {
        let schema = writer.add_schema(msg_type, "ros2msg", b"# the definition").expect("schema");
        channels.push(writer.add_channel(schema, topic, "cdr", &BTreeMap::new()).expect("channel"));
    }
    for (i, message) in expected().iter().enumerate() {
        let header = MessageHeader {
            channel_id: channels[i % TOPICS.len()],
            sequence: i as u32,
            log_time: message.log_time_ns,
            publish_time: message.log_time_ns,
        };
        writer.write_to_known_channel(&header, &message.data).expect("message");
        if (i + 1) % PER_CHUNK == 0 {
            writer.flush().expect("flush");
        }
    }
    writer.finish().expect("finish");
    writer.into_inner().into_inner()
}

fn variants() -> Vec<(&'static str, WriteOptions)> {
    vec![
        ("uncompressed", WriteOptions::new().compression(None)),
        ("zstd", WriteOptions::new().compression(Some(Compression::Zstd))),
        ("lz4", WriteOptions::new().compression(Some(Compression::Lz4))),
        ("unchunked", WriteOptions::new().use_chunks(false)),
    ]
}

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    replace(&path, bytes);
    path
}

/// Writes a new file at `path`: truncating the old one instead would
/// make ext4 flush it to disk on close, a thousand times a test.
fn replace(path: &Path, bytes: &[u8]) {
    let _ = std::fs::remove_file(path);
    std::fs::write(path, bytes).expect("write the test file");
}

fn read(path: &Path, topics: &[String]) -> Vec<Result<RawMessage, IoError>> {
    McapReader::open(path).expect("open").messages(topics).collect()
}

/// Leading `Ok` messages and the errors after them.
fn split(items: Vec<Result<RawMessage, IoError>>) -> (Vec<RawMessage>, Vec<IoError>) {
    let mut messages = Vec::new();
    let mut errors = Vec::new();
    for item in items {
        match item {
            Ok(message) if errors.is_empty() => messages.push(message),
            Ok(message) => panic!("message {message:?} after an error"),
            Err(e) => errors.push(e),
        }
    }
    (messages, errors)
}

/// Top-level records `(offset, opcode)` up to the footer.
fn top_records(bytes: &[u8]) -> Vec<(usize, u8)> {
    split_records(&bytes[MAGIC.len()..])
        .map_while(Result::ok)
        .map(|(at, opcode, _)| (at + MAGIC.len(), opcode))
        .collect()
}

fn offsets_of(bytes: &[u8], opcode: u8) -> Vec<usize> {
    top_records(bytes).into_iter().filter(|&(_, op)| op == opcode).map(|(at, _)| at).collect()
}

#[test]
fn reads_back_what_was_written() {
    let dir = tempfile::tempdir().expect("temp dir");
    let all = expected();
    for (name, options) in variants() {
        let path = write(&dir, &format!("{name}.mcap"), &recording(options));
        let mcap = McapReader::open(&path).expect("open");
        let mut file = File::open(&path).expect("file");
        assert!(summary_topics(&mut file, &path).expect("summary").is_some(), "{name}: no summary read");
        assert_eq!(mcap.topics().expect("topics"), expected_topics(&all), "{name}");
        let topic_list = mcap.topics().expect("topics");
        assert_eq!(topic_list[0].msg_type, "nav_msgs/Odometry");
        assert_eq!(topic_list.iter().map(|t| t.messages).sum::<u64>(), MESSAGES as u64);
        let messages: Vec<_> = mcap.messages(&[]).collect::<Result<_, _>>().expect("messages");
        assert_eq!(messages, all, "{name}");
        let tf = ["/tf".to_string()];
        let messages: Vec<_> = mcap.messages(&tf).collect::<Result<_, _>>().expect("messages");
        let want: Vec<_> = all.iter().filter(|m| m.topic == "/tf").cloned().collect();
        assert_eq!(messages, want, "{name}");
        assert!(mcap.messages(&["/nothing".to_string()]).next().is_none());
    }
}

#[test]
fn topics_without_a_summary_come_from_a_scan() {
    let dir = tempfile::tempdir().expect("temp dir");
    let options = WriteOptions::new().emit_summary_records(false).emit_summary_offsets(false);
    let path = write(&dir, "bare.mcap", &recording(options));
    let mut file = File::open(&path).expect("file");
    assert!(summary_topics(&mut file, &path).expect("summary").is_none());
    let mcap = McapReader::open(&path).expect("open");
    assert_eq!(mcap.topics().expect("topics"), expected_topics(&expected()));
    assert_eq!(split(read(&path, &[])).0, expected());
}

#[test]
fn damaged_summary_falls_back_to_a_scan() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = recording(WriteOptions::new());
    let statistics = top_records(&bytes).into_iter().find(|&(_, op)| op == op::STATISTICS).expect("stats");
    bytes[statistics.0 + RECORD_PREFIX] ^= 0x40; // the message count
    let path = write(&dir, "summary.mcap", &bytes);
    let mut file = File::open(&path).expect("file");
    assert!(summary_topics(&mut file, &path).expect("summary").is_none(), "CRC mismatch unseen");
    let mcap = McapReader::open(&path).expect("open");
    assert_eq!(mcap.topics().expect("topics"), expected_topics(&expected()));
    let (messages, errors) = split(read(&path, &[]));
    assert!(messages == expected() && errors.is_empty(), "{errors:?}");
}

#[test]
fn killed_recorder_gives_every_complete_chunk() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, options) in variants().into_iter().take(3) {
        let bytes = recording(options);
        let data_end = offsets_of(&bytes, op::DATA_END)[0];
        let last_chunk = *offsets_of(&bytes, op::CHUNK).last().expect("chunks");
        for (cut, kept) in [(data_end, MESSAGES), (last_chunk + 40, MESSAGES - PER_CHUNK)] {
            let path = write(&dir, &format!("{name}-{cut}.mcap"), &bytes[..cut]);
            let (messages, errors) = split(read(&path, &[]));
            assert_eq!(messages, expected()[..kept], "{name} cut at {cut}");
            assert_eq!(errors.len(), 1, "{name} cut at {cut}");
            let error = errors[0].to_string();
            assert!(error.contains("truncated") && error.contains(&path.display().to_string()), "{error}");
            let topics = McapReader::open(&path).expect("open").topics().expect("topics");
            assert_eq!(topics, expected_topics(&expected()[..kept]), "{name} cut at {cut}");
        }
    }
}

#[test]
fn truncation_anywhere_gives_a_prefix_then_one_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let all = expected();
    for (name, options) in variants() {
        let bytes = recording(options);
        let data_end = offsets_of(&bytes, op::DATA_END)[0] + RECORD_PREFIX + 4;
        let path = dir.path().join(format!("{name}.mcap"));
        let mut kept_before = 0;
        // Every offset of the start and around each record boundary,
        // every 11th elsewhere.
        let starts: Vec<_> = top_records(&bytes).into_iter().map(|(at, _)| at).collect();
        let near_start = |cut: usize| starts.iter().any(|&at| cut.abs_diff(at) <= 10);
        for cut in (0..bytes.len()).filter(|&cut| cut < 400 || cut % 11 == 0 || near_start(cut)) {
            replace(&path, &bytes[..cut]);
            let Ok(mcap) = McapReader::open(&path) else {
                assert!(cut < MAGIC.len(), "{name}: open failed with {cut} bytes");
                continue;
            };
            let (messages, errors) = split(mcap.messages(&[]).collect());
            assert_eq!(messages, all[..messages.len()], "{name} cut at {cut}");
            assert!(messages.len() >= kept_before, "{name} cut at {cut}: fewer messages than a shorter cut");
            kept_before = messages.len();
            if cut < data_end {
                assert_eq!(errors.len(), 1, "{name} cut at {cut}");
                assert!(errors[0].to_string().contains("byte"), "{}", errors[0]);
            } else {
                assert!(errors.is_empty() && messages.len() == MESSAGES, "{name} cut at {cut}: {errors:?}");
            }
            let counted: u64 = mcap.topics().expect("topics").iter().map(|t| t.messages).sum();
            assert!(counted >= messages.len() as u64 && counted <= MESSAGES as u64, "{name} cut at {cut}");
        }
    }
}

/// A recording with a JSON, a ROS 1 and a schema-less CDR channel besides
/// a ROS 2 one.
fn mixed_recording() -> Vec<u8> {
    let mut writer = WriteOptions::new().create(Cursor::new(Vec::new())).expect("writer");
    let json = writer.add_schema("Chat", "jsonschema", b"{}").expect("schema");
    let tf = writer.add_schema("tf2_msgs/msg/TFMessage", "ros2msg", b"").expect("schema");
    let ros1 = writer.add_schema("sensor_msgs/Imu", "ros1msg", b"").expect("schema");
    let none = BTreeMap::new();
    let channels = [
        writer.add_channel(tf, "/tf", "cdr", &none).expect("channel"),
        writer.add_channel(json, "/chat", "json", &none).expect("channel"),
        writer.add_channel(ros1, "/imu", "ros1", &none).expect("channel"),
        writer.add_channel(0, "/raw", "cdr", &none).expect("channel"),
    ];
    for (i, &channel_id) in channels.iter().cycle().take(8).enumerate() {
        let header = MessageHeader { channel_id, sequence: i as u32, log_time: i as u64, publish_time: 0 };
        writer.write_to_known_channel(&header, &[i as u8; 8]).expect("message");
    }
    writer.finish().expect("finish");
    writer.into_inner().into_inner()
}

#[test]
fn other_encodings_are_refused_only_when_asked_for() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write(&dir, "mixed.mcap", &mixed_recording());
    let topics = |names: &[&str]| names.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let (messages, errors) = split(read(&path, &topics(&["/tf", "/imu", "/raw"])));
    assert!(errors.is_empty(), "{errors:?}");
    let kinds: Vec<_> = messages.iter().map(|m| (m.topic.as_str(), m.msg_type.as_str(), m.encoding)).collect();
    let round = [
        ("/tf", "tf2_msgs/TFMessage", Encoding::Cdr),
        ("/imu", "sensor_msgs/Imu", Encoding::Ros1),
        ("/raw", "", Encoding::Cdr),
    ];
    assert_eq!(kinds, [round, round].concat());
    for asked in [topics(&["/chat"]), vec![]] {
        let (messages, errors) = split(read(&path, &asked));
        assert_eq!(messages.len(), usize::from(asked.is_empty()), "the /tf message before the first /chat one");
        assert_eq!(errors.len(), 1);
        let error = errors[0].to_string();
        assert!(error.contains("/chat") && error.contains("\"json\""), "{error}");
    }
    let listed = McapReader::open(&path).expect("open").topics().expect("topics");
    let listed: Vec<_> = listed.iter().map(|t| (t.topic.as_str(), t.msg_type.as_str(), t.messages)).collect();
    let want =
        [("/chat", "Chat", 2), ("/imu", "sensor_msgs/Imu", 2), ("/raw", "", 2), ("/tf", "tf2_msgs/TFMessage", 2)];
    assert_eq!(listed, want);
}

#[test]
fn garbage_is_not_an_mcap_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = StdRng::seed_from_u64(7);
    let noise: Vec<u8> = (0..1000).map(|_| rng.random()).collect();
    for (name, bytes) in [("noise", &noise[..]), ("empty", &[][..]), ("short", &MAGIC[..5])] {
        let path = write(&dir, name, bytes);
        let error = McapReader::open(&path).expect_err(name).to_string();
        assert!(error.contains("not an MCAP file") && error.contains(name), "{error}");
    }
    let error = McapReader::open(&dir.path().join("missing.mcap")).expect_err("missing");
    assert!(matches!(error, IoError::Io { .. }), "{error}");
    let path = write(&dir, "magic-only.mcap", MAGIC);
    let mcap = McapReader::open(&path).expect("open");
    assert_eq!(mcap.topics().expect("topics"), vec![]);
    let (messages, errors) = split(mcap.messages(&[]).collect());
    assert!(messages.is_empty() && errors.len() == 1 && errors[0].to_string().contains("truncated"));
}

#[test]
fn damaged_chunk_gives_no_message() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, options) in variants().into_iter().take(3) {
        let mut bytes = recording(options);
        let third = offsets_of(&bytes, op::CHUNK)[2];
        let len = u64::from_le_bytes(bytes[third + 1..third + RECORD_PREFIX].try_into().expect("8 bytes"));
        bytes[third + RECORD_PREFIX + len as usize - 20] ^= 0x10;
        let path = write(&dir, &format!("{name}.mcap"), &bytes);
        let (messages, errors) = split(read(&path, &[]));
        assert_eq!(messages, expected()[..2 * PER_CHUNK], "{name}");
        assert_eq!(errors.len(), 1, "{name}");
        let error = errors[0].to_string();
        assert!(error.contains(&format!("the chunk at byte {third}")), "{name}: {error}");
    }
}

#[test]
fn unknown_compression_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = recording(WriteOptions::new().compression(Some(Compression::Zstd)));
    let second = offsets_of(&bytes, op::CHUNK)[1];
    let at = second + bytes[second..].windows(4).position(|w| w == b"zstd").expect("compression");
    bytes[at..at + 4].copy_from_slice(b"brot");
    let path = write(&dir, "brot.mcap", &bytes);
    let (messages, errors) = split(read(&path, &[]));
    assert_eq!(messages, expected()[..PER_CHUNK]);
    assert!(errors.len() == 1 && errors[0].to_string().contains("\"brot\""), "{errors:?}");
}

#[test]
fn mutated_files_never_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut originals: Vec<Vec<u8>> = variants().into_iter().map(|(_, options)| recording(options)).collect();
    originals.push(mixed_recording());
    // Without chunk CRCs, damage inside a chunk reaches the record walk.
    for compression in [None, Some(Compression::Lz4), Some(Compression::Zstd)] {
        originals.push(recording(WriteOptions::new().compression(compression).calculate_chunk_crcs(false)));
    }
    let cases: usize = std::env::var("MCAP_FUZZ_CASES").ok().and_then(|n| n.parse().ok()).unwrap_or(2000);
    let mut outcomes = [0usize; 5];
    let path = dir.path().join("mutant.mcap");
    let mut rng = StdRng::seed_from_u64(2024);
    for case in 0..cases {
        let mut bytes = originals[case % originals.len()].clone();
        for _ in 0..rng.random_range(1..=4) {
            let at = rng.random_range(0..bytes.len());
            match rng.random_range(0..4) {
                0 => bytes[at] ^= 1 << rng.random_range(0..8),
                1 => bytes[at] = rng.random(),
                2 => bytes.splice(at..at, (0..rng.random_range(1..16)).map(|_| rng.random::<u8>())).for_each(drop),
                _ => bytes.truncate(at.max(1)),
            }
        }
        replace(&path, &bytes);
        let Ok(mcap) = McapReader::open(&path) else {
            outcomes[0] += 1;
            continue;
        };
        let _ = mcap.topics();
        let (messages, errors) = split(mcap.messages(&[]).collect());
        assert!(errors.len() <= 1, "case {case}: {} messages, errors {errors:?}", messages.len());
        outcomes[1 + 2 * usize::from(!errors.is_empty()) + usize::from(messages.is_empty())] += 1;
    }
    eprintln!("not opened; no damage seen: messages, none; damage: after messages, before any: {outcomes:?}");
}
