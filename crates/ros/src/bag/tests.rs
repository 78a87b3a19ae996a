//! Round trips through the writer, bags killed mid-run or cut short, the
//! `rosbag` crate as a second reader, and random damage.

use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::format::op;
use super::{BagReader, BagWriter};
use crate::{Encoding, RawMessage, TopicInfo};
use edtmap_io::IoError;

/// (topic, type, md5sum) of the sample bags.
const TOPICS: [(&str, &str, &str); 3] = [
    ("/velodyne_points", "sensor_msgs/PointCloud2", "1158d486dd51d683ce2f1be655c3c181"),
    ("/tf", "tf2_msgs/TFMessage", "94810edda583a504dfda3829e70d7eec"),
    ("/odom", "nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7"),
];

/// The messages of the sample bags: topics in a mixed order, times
/// increasing, payloads of varied lengths (empty included).
fn sample_messages(n: usize) -> Vec<RawMessage> {
    (0..n)
        .map(|i| {
            let (topic, msg_type, _) = TOPICS[(i * 7 / 3) % 3];
            RawMessage {
                topic: topic.into(),
                msg_type: msg_type.into(),
                log_time_ns: 1_700_000_000_000_000_000 + i as u64 * 33_333_333,
                data: (0..(i * 37) % 300).map(|k| (i * 31 + k) as u8).collect(),
                encoding: Encoding::Ros1,
            }
        })
        .collect()
}

/// Writes `messages` to `path` in chunks of about `chunk_bytes`; finished
/// (indexed) or left as a killed recorder leaves it.
fn write_bag(path: &Path, messages: &[RawMessage], chunk_bytes: u32, finish: bool) {
    let mut writer = BagWriter::create(path).expect("create").with_chunk_bytes(chunk_bytes);
    let mut ids = Vec::new();
    for (topic, msg_type, md5) in TOPICS {
        ids.push(writer.add_connection(topic, msg_type, md5, "# a definition\nuint8[] data\n").expect("connection"));
    }
    for m in messages {
        let conn = TOPICS.iter().position(|t| t.0 == m.topic).expect("sample topic");
        writer.write(ids[conn], m.log_time_ns, &m.data).expect("write");
    }
    if finish {
        writer.finish().expect("finish");
    } else {
        writer.finish_unindexed().expect("finish unindexed");
    }
}

/// The bag's `Ok` messages and its errors, in order.
fn read_all(reader: &BagReader, topics: &[String]) -> (Vec<RawMessage>, Vec<IoError>) {
    let (mut ok, mut errors) = (Vec::new(), Vec::new());
    for m in reader.messages(topics) {
        match m {
            Ok(m) if errors.is_empty() => ok.push(m),
            Ok(m) => panic!("message {} after an error", m.topic),
            Err(e) => errors.push(e),
        }
    }
    (ok, errors)
}

/// The topics `messages` lists, as `topics()` should give them.
fn topic_counts(messages: &[RawMessage]) -> Vec<TopicInfo> {
    let mut topics: Vec<TopicInfo> = TOPICS
        .iter()
        .map(|(topic, msg_type, _)| TopicInfo {
            topic: topic.to_string(),
            msg_type: msg_type.to_string(),
            messages: messages.iter().filter(|m| m.topic == *topic).count() as u64,
        })
        .collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    topics
}

/// Writes `bytes` to a new file at `path`: rewriting a file in place makes
/// some file systems (ext4's `auto_da_alloc`) flush it, slow in a loop.
fn replace(path: &Path, bytes: &[u8]) {
    let _ = std::fs::remove_file(path);
    std::fs::write(path, bytes).expect("write");
}

fn temp_bag() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("test.bag");
    (dir, path)
}

#[test]
fn round_trip_keeps_messages_order_and_topics() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(60);
    write_bag(&path, &messages, 1000, true);
    let reader = BagReader::open(&path).expect("open");
    assert!(reader.has_index());
    let (read, errors) = read_all(&reader, &[]);
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(read, messages);
    assert_eq!(reader.topics().expect("topics"), topic_counts(&messages));

    let wanted = ["/tf".to_string(), "/odom".to_string()];
    let (read, errors) = read_all(&reader, &wanted);
    assert!(errors.is_empty(), "{errors:?}");
    let expected: Vec<_> = messages.iter().filter(|m| wanted.contains(&m.topic)).cloned().collect();
    assert_eq!(read, expected);
}

#[test]
fn empty_bag_has_no_topics_and_no_messages() {
    let (_dir, path) = temp_bag();
    BagWriter::create(&path).expect("create").finish().expect("finish");
    let reader = BagReader::open(&path).expect("open");
    assert_eq!(reader.topics().expect("topics"), vec![]);
    assert_eq!(reader.messages(&[]).count(), 0);
}

#[test]
fn bag_never_finished_reads_every_message() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(50);
    write_bag(&path, &messages, 1500, false);
    let reader = BagReader::open(&path).expect("open");
    assert_eq!(reader.index_pos, 0);
    let (read, errors) = read_all(&reader, &[]);
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(read, messages);
    assert_eq!(reader.topics().expect("topics"), topic_counts(&messages));
}

#[test]
fn index_counts_agree_with_a_scan() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(40);
    write_bag(&path, &messages, 700, true);
    let reader = BagReader::open(&path).expect("open");
    let from_index = reader.topics().expect("topics");
    // The same bag without its index is scanned.
    let bytes = std::fs::read(&path).expect("read");
    std::fs::write(&path, &bytes[..reader.index_pos as usize]).expect("write");
    let cut = BagReader::open(&path).expect("open");
    assert_eq!(cut.topics().expect("topics"), from_index);
}

/// The `rosbag` crate reads the written bag through both its chunk and its
/// index sections, and they agree with what was written.
#[test]
fn rosbag_crate_reads_the_written_bag() {
    use rosbag::{ChunkRecord, IndexRecord, MessageRecord, RosBag};
    let (_dir, path) = temp_bag();
    let messages = sample_messages(45);
    write_bag(&path, &messages, 900, true);
    let bag = RosBag::new(&path).expect("rosbag opens it");
    let (mut read, mut chunks) = (Vec::new(), 0);
    let mut conns = std::collections::HashMap::new();
    for record in bag.chunk_records() {
        if let ChunkRecord::Chunk(chunk) = record.expect("chunk section record") {
            chunks += 1;
            for m in chunk.messages() {
                match m.expect("chunk record") {
                    MessageRecord::Connection(c) => {
                        conns.insert(c.id, (c.topic.to_string(), c.tp.to_string()));
                    }
                    MessageRecord::MessageData(m) => read.push((conns[&m.conn_id].0.clone(), m.time, m.data.to_vec())),
                }
            }
        }
    }
    let expected: Vec<_> = messages.iter().map(|m| (m.topic.clone(), m.log_time_ns, m.data.clone())).collect();
    assert_eq!(read, expected);
    assert!(chunks > 3, "{chunks} chunks");
    assert_eq!(bag.get_chunk_count(), chunks);

    let (mut infos, mut counted) = (0, 0u64);
    for record in bag.index_records() {
        match record.expect("index record") {
            IndexRecord::Connection(c) => assert_eq!(conns[&c.id], (c.topic.to_string(), c.tp.to_string())),
            IndexRecord::ChunkInfo(info) => {
                infos += 1;
                counted += info.entries().map(|e| u64::from(e.count)).sum::<u64>();
            }
            IndexRecord::IndexData(_) => panic!("index data in the index section"),
        }
    }
    assert_eq!((infos, counted), (chunks, messages.len() as u64));
    assert_eq!(bag.get_conn_count(), TOPICS.len() as u32);
}

/// A closed bag cut anywhere before its index gives a prefix of its
/// messages then one error; cut inside the index, all of them.
#[test]
fn truncated_bag_gives_a_prefix_then_one_error() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(30);
    write_bag(&path, &messages, 800, true);
    let bytes = std::fs::read(&path).expect("read");
    let whole = BagReader::open(&path).expect("open");
    let cut_path = path.with_file_name("cut.bag");
    let mut last_count = 0;
    let mut cuts: Vec<usize> =
        (0..bytes.len()).step_by(7).chain([whole.chunks_at as usize, whole.index_pos as usize]).collect();
    cuts.sort();
    for cut in cuts {
        replace(&cut_path, &bytes[..cut]);
        let Ok(reader) = BagReader::open(&cut_path) else {
            assert!((cut as u64) < whole.chunks_at, "refused a bag cut at {cut}");
            continue;
        };
        let (read, errors) = read_all(&reader, &[]);
        assert_eq!(read[..], messages[..read.len()], "cut at {cut}");
        if (cut as u64) < whole.index_pos {
            assert_eq!(errors.len(), 1, "cut at {cut}");
            assert!(errors[0].to_string().contains("cut.bag: byte "), "{}", errors[0]);
        } else {
            assert!(errors.is_empty() && read.len() == messages.len(), "cut at {cut}: {errors:?}");
        }
        assert!(read.len() >= last_count || (cut as u64) < whole.chunks_at);
        last_count = read.len();
        let listed: u64 = reader.topics().expect("topics").iter().map(|t| t.messages).sum();
        assert_eq!(listed, read.len() as u64, "cut at {cut}");
    }
}

/// A bag never closed ends without an error when cut between records and
/// with one when cut inside a record.
#[test]
fn unfinished_bag_cut_between_records_ends_cleanly() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(20);
    write_bag(&path, &messages, 600, false);
    let bytes = std::fs::read(&path).expect("read");
    let chunks_at = BagReader::open(&path).expect("open").chunks_at as usize;
    let boundaries = record_ends(&bytes, chunks_at);
    let cut_path = path.with_file_name("cut.bag");
    for cut in chunks_at..=bytes.len() {
        replace(&cut_path, &bytes[..cut]);
        let reader = BagReader::open(&cut_path).expect("open");
        let (read, errors) = read_all(&reader, &[]);
        assert_eq!(read[..], messages[..read.len()], "cut at {cut}");
        assert_eq!(errors.len(), usize::from(!boundaries.contains(&cut)), "cut at {cut}: {errors:?}");
    }
}

/// Offsets where top-level records end, and where the records of a chunk
/// end (the chunk is then cut short but what it holds is whole), from
/// `start`; the chunks with sizes 0 of a killed recorder hold no records.
fn record_ends(bytes: &[u8], start: usize) -> Vec<usize> {
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) as usize;
    let mut ends = vec![start];
    let mut at = start;
    while at < bytes.len() {
        let data_at = at + 4 + u32_at(at) + 4;
        ends.push(data_at + u32_at(data_at - 4));
        at = *ends.last().expect("pushed");
    }
    ends
}

#[test]
fn not_a_bag_is_refused_clearly() {
    let (_dir, path) = temp_bag();
    let cases: [(&[u8], &str); 4] = [
        (b"", "not a ROS bag"),
        (b"PK\x03\x04 this is a zip file, not a bag at all", "not a ROS bag"),
        (b"#ROSBAG V1.2\nold format with some more bytes", "other than 2.0"),
        (b"#ROSBAG V2.0\n\xff\xff\xff\xff\x00\x00\x00\x00", "not plausible"),
    ];
    for (bytes, says) in cases {
        std::fs::write(&path, bytes).expect("write");
        let e = BagReader::open(&path).expect_err("not a bag");
        assert!(matches!(e, IoError::Dataset { .. }), "{e:?}");
        assert!(e.to_string().contains("test.bag") && e.to_string().contains(says), "{e}");
    }
    let e = BagReader::open(Path::new("/nonexistent/x.bag")).expect_err("no file");
    assert!(matches!(e, IoError::Io { .. }));
}

#[test]
fn unknown_compression_and_undefined_connection_are_errors() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(10);
    write_bag(&path, &messages, 100_000, true);
    let bytes = std::fs::read(&path).expect("read");
    let find = |needle: &[u8]| bytes.windows(needle.len()).position(|w| w == needle).expect("present");

    let mut zstd = bytes.clone();
    let at = find(b"compression=none");
    zstd[at + 12..at + 16].copy_from_slice(b"zstd");
    std::fs::write(&path, &zstd).expect("write");
    let (read, errors) = read_all(&BagReader::open(&path).expect("open"), &[]);
    assert!(read.is_empty() && errors[0].to_string().contains("unknown chunk compression `zstd`"), "{errors:?}");

    // The first message names connection 9 instead of its own.
    let mut stray = bytes.clone();
    // A message header starts `op=\x02`, then `conn=`.
    let conn = find(&[4, 0, 0, 0, b'o', b'p', b'=', op::MESSAGE_DATA, 9, 0, 0, 0]) + 8 + 4 + 5;
    stray[conn..conn + 4].copy_from_slice(&9u32.to_le_bytes());
    std::fs::write(&path, &stray).expect("write");
    let (read, errors) = read_all(&BagReader::open(&path).expect("open"), &[]);
    assert!(read.is_empty() && errors[0].to_string().contains("connection 9"), "{errors:?}");
}

/// Random bytes, and valid bags with random damage, never panic; the
/// iterator always ends, with at most one error, last.
#[test]
fn never_panics_on_random_or_mutated_input() {
    let (_dir, path) = temp_bag();
    let messages = sample_messages(12);
    write_bag(&path, &messages, 400, true);
    let finished = std::fs::read(&path).expect("read");
    write_bag(&path, &messages, 400, false);
    let killed = std::fs::read(&path).expect("read");
    let chunks_at = BagReader::open(&path).expect("open").chunks_at as usize;
    let nasty: [&[u8]; 8] = [
        &[0xff, 0xff, 0xff, 0xff],
        &[0, 0, 0, 0],
        &[0xff, 0xff, 0xff, 0x7f],
        b"op=\x05",
        b"op=\x07",
        b"compression=bz2",
        b"compression=lz4",
        &[9, 0, 0, 0],
    ];
    let mut rng = StdRng::seed_from_u64(0xba6_f11e);
    let (mut read_ok, mut refused) = (0, 0);
    for i in 0..2000 {
        let bytes: Vec<u8> = if i % 20 == 0 {
            let mut b = b"#ROSBAG V2.0\n".to_vec();
            b.extend((0..rng.random_range(0..600)).map(|_| rng.random::<u8>()));
            b
        } else {
            let mut b = if i % 2 == 0 { finished.clone() } else { killed.clone() };
            for _ in 0..rng.random_range(1..4) {
                // Mostly outside the bag header's padding, where damage shows.
                let at = if rng.random_bool(0.2) {
                    rng.random_range(0..=60.min(b.len()))
                } else {
                    rng.random_range(chunks_at.min(b.len())..=b.len())
                };
                match rng.random_range(0..5) {
                    0 if at < b.len() => b[at] = rng.random(),
                    1 => b.truncate(at),
                    2 => {
                        let end = (at + rng.random_range(0..16)).min(b.len());
                        b.drain(at..end);
                    }
                    _ => {
                        let piece = nasty[rng.random_range(0..nasty.len())];
                        let end = (at + piece.len()).min(b.len());
                        if rng.random_bool(0.5) {
                            b.splice(at..end, piece.iter().copied())
                        } else {
                            b.splice(at..at, piece.iter().copied())
                        };
                    }
                }
            }
            b
        };
        replace(&path, &bytes);
        let Ok(reader) = BagReader::open(&path) else {
            refused += 1;
            continue;
        };
        let _ = reader.topics();
        let (read, errors) = read_all(&reader, &[]);
        assert!(errors.len() <= 1 && read.len() <= 64, "case {i}");
        read_ok += usize::from(errors.is_empty());
    }
    assert!(read_ok > 100 && refused > 50, "{read_ok} read whole, {refused} refused");
}

/// `compressed_payload()` compressed by Python's `bz2.compress`.
const BZ2_PAYLOAD: &str = "425a6839314159265359b09ced8a00003bfbc07efa0400e180bfe20800bfe7de6020003000ba50d427a53f5236a7a26d234681a0f50d0f53d0430003469a00c9a0341901a03252793537a91ea791a80680000192c285d1116d2c75cea502bdc595d4f31101528209880800442f78b5c43ad7e1f8c24bd88f535afeef25b3490793484ba3f208450b19a24b7a8b098e84949519c8988b97739483a5b095bee195061dba72a6fc0ddb0595d4c18ea0916cce5bf44d7512095b8ec61433cd133950d3240b784a116582d83546040ac94adf6327fe2ee48a70a1216139db14";
/// `compressed_payload()` compressed by the `lz4` command (an LZ4 frame).
const LZ4_PAYLOAD: &str = "04224d18604082d3000000fb1721000000040000006f703d0709000000636f6e6e3d0000000008000000746f7069633d2f6381100010141c00f0307970653d7374645f6d7367732f537472696e67270000006d643573756d3d39393263653861313638376365633863386264383833656337336361343164311f2b00f1046573736167655f646566696e6974696f6e3d7348007020646174610a0b8f00b6616c6c657269643d2f7826aa001902aa00100d8e00c0696d653d01000000050000001e000008005f68656c6c6f37000f5302000000070400700300000062796500000000";

/// A connection record for `/c` (`std_msgs/String`) and the whole chunk
/// payload: that record and two messages.
fn compressed_payload() -> (Vec<u8>, Vec<u8>) {
    use super::format::{put_field, record};
    let mut header = Vec::new();
    for (name, value) in [
        ("topic", "/c"),
        ("type", "std_msgs/String"),
        ("md5sum", "992ce8a1687cec8c8bd883ec73ca41d1"),
        ("message_definition", "string data\n"),
        ("callerid", "/x"),
    ] {
        put_field(&mut header, name, value.as_bytes());
    }
    let conn = record(&[("op", &[op::CONNECTION]), ("conn", &0u32.to_le_bytes()), ("topic", b"/c")], &header);
    let mut payload = conn.clone();
    for (secs, nsecs, data) in [(1u32, 5u32, &b"\x05\0\0\0hello"[..]), (2, 7, b"\x03\0\0\0bye")] {
        let time = [secs.to_le_bytes(), nsecs.to_le_bytes()].concat();
        payload.extend(record(&[("op", &[op::MESSAGE_DATA]), ("conn", &0u32.to_le_bytes()), ("time", &time)], data));
    }
    (conn, payload)
}

/// A bag of one `compression` chunk holding `compressed`; its header
/// points at the index when `indexed`, else says 0 like a killed recorder.
fn compressed_bag(compression: &str, compressed: &[u8], indexed: bool) -> Vec<u8> {
    use super::format::{record, MAGIC};
    let (conn, payload) = compressed_payload();
    let chunk_at = (MAGIC.len() + super::writer::bag_header(0, 0, 0).len()) as u64;
    let size = (payload.len() as u32).to_le_bytes();
    let chunk = record(&[("op", &[op::CHUNK]), ("compression", compression.as_bytes()), ("size", &size)], compressed);
    let index_pos = chunk_at + chunk.len() as u64;
    let times = [1u32.to_le_bytes(), 5u32.to_le_bytes(), 2u32.to_le_bytes(), 7u32.to_le_bytes()].concat();
    let info = record(
        &[
            ("op", &[op::CHUNK_INFO]),
            ("ver", &1u32.to_le_bytes()),
            ("chunk_pos", &chunk_at.to_le_bytes()),
            ("start_time", &times[..8]),
            ("end_time", &times[8..]),
            ("count", &1u32.to_le_bytes()),
        ],
        &[0u32.to_le_bytes(), 2u32.to_le_bytes()].concat(),
    );
    let mut bag = MAGIC.to_vec();
    bag.extend(super::writer::bag_header(if indexed { index_pos } else { 0 }, 1, 1));
    bag.extend(chunk);
    bag.extend(conn);
    bag.extend(info);
    bag
}

fn unhex(hex: &str) -> Vec<u8> {
    (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex")).collect()
}

#[test]
fn compressed_chunks_are_decoded() {
    let (_dir, path) = temp_bag();
    for (compression, hex) in [("bz2", BZ2_PAYLOAD), ("lz4", LZ4_PAYLOAD)] {
        std::fs::write(&path, compressed_bag(compression, &unhex(hex), true)).expect("write");
        let reader = BagReader::open(&path).expect("open");
        let (read, errors) = read_all(&reader, &[]);
        assert!(errors.is_empty(), "{compression}: {errors:?}");
        let got: Vec<_> =
            read.iter().map(|m| (m.topic.as_str(), m.msg_type.as_str(), m.log_time_ns, &m.data[4..])).collect();
        let expected =
            [("/c", "std_msgs/String", 1_000_000_005, &b"hello"[..]), ("/c", "std_msgs/String", 2_000_000_007, b"bye")];
        assert_eq!(got, expected, "{compression}");
        let topics = reader.topics().expect("topics");
        assert_eq!(topics, [TopicInfo { topic: "/c".into(), msg_type: "std_msgs/String".into(), messages: 2 }]);

        // Without an index the rosbag crate cannot be asked for the chunk.
        std::fs::write(&path, compressed_bag(compression, &unhex(hex), false)).expect("write");
        let (read, errors) = read_all(&BagReader::open(&path).expect("open"), &[]);
        assert!(read.is_empty() && errors[0].to_string().contains("reindex"), "{errors:?}");

        // A damaged stream is an error, not a panic.
        let mut damaged = unhex(hex);
        let mid = damaged.len() / 2;
        damaged[mid..].iter_mut().for_each(|b| *b = b.wrapping_mul(7));
        std::fs::write(&path, compressed_bag(compression, &damaged, true)).expect("write");
        let (_, errors) = read_all(&BagReader::open(&path).expect("open"), &[]);
        assert_eq!(errors.len(), 1, "{compression}");
    }
}
