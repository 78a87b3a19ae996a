//! The DDS transport the node uses, on its own: large samples between two
//! participants over loopback, where a reader's socket buffer is smaller
//! than one sample (as a Fast DDS reader's default 208 KiB is for a
//! multi-megabyte ESDF cloud), and fragmented samples that carry a
//! request id (service requests and replies).

use ros2_client::dds::rustdds::policy::{History, Reliability};
use ros2_client::dds::rustdds::rpc::SampleIdentity;
use ros2_client::dds::rustdds::{
    DomainParticipant, DomainParticipantBuilder, QosPolicies, QosPolicyBuilder, RTPSEntity, SequenceNumber, TopicKind,
    WriteOptionsBuilder,
};
use serde::{Deserialize, Serialize};
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Blob {
    id: u32,
    #[serde(with = "serde_bytes")]
    bytes: Vec<u8>,
}

fn participant(domain: u16, receive_buffer: Option<usize>) -> DomainParticipant {
    let mut b = DomainParticipantBuilder::new(domain).with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
    if let Some(n) = receive_buffer {
        b = b.socket_receive_buffer_size(n);
    }
    b.build().expect("participant")
}

fn reliable() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::Reliable { max_blocking_time: ros2_client::dds::rustdds::Duration::from_secs(5) })
        .history(History::KeepLast { depth: 4 })
        .build()
}

/// A seeded, incompressible payload of `n` bytes.
fn payload(n: usize, seed: u32) -> Vec<u8> {
    let mut x = 0x9e37_79b9_u32 ^ seed;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

/// Writes `count` samples of `size` bytes, one after the other arrives,
/// optionally as replies (with a related sample identity), and returns how
/// long each took to arrive; fails if one does not within `limit`.
fn send_and_receive(domain: u16, size: usize, count: u32, as_reply: bool, limit: Duration) -> Vec<Duration> {
    let writer_p = participant(domain, None);
    // The smallest receive buffer Linux grants an unprivileged socket by
    // default is about this (rmem_default, 208 KiB): what a Fast DDS
    // reader has unless configured otherwise.
    let reader_p = participant(domain, Some(212_992));
    let qos = reliable();
    let name = format!("large_{size}_{as_reply}");
    let topic_w = writer_p.create_topic(name.clone(), "Blob".into(), &qos, TopicKind::NoKey).expect("topic");
    let topic_r = reader_p.create_topic(name, "Blob".into(), &qos, TopicKind::NoKey).expect("topic");
    let writer = writer_p
        .create_publisher(&qos)
        .expect("publisher")
        .create_datawriter_no_key_cdr::<Blob>(&topic_w, None)
        .expect("writer");
    let mut reader = reader_p
        .create_subscriber(&qos)
        .expect("subscriber")
        .create_datareader_no_key_cdr::<Blob>(&topic_r, None)
        .expect("reader");

    // Discovery: small samples until one arrives, then the large ones.
    let until = Instant::now() + Duration::from_secs(10);
    'discovery: loop {
        writer.write(Blob { id: u32::MAX, bytes: vec![1] }, None).expect("write");
        for _ in 0..50 {
            if let Ok(Some(_)) = reader.take_next_sample() {
                break 'discovery;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        assert!(Instant::now() < until, "the participants did not discover each other");
    }
    while let Ok(Some(_)) = reader.take_next_sample() {}

    let mut took = Vec::new();
    for id in 0..count {
        let blob = Blob { id, bytes: payload(size, id) };
        let start = Instant::now();
        if as_reply {
            let related = SampleIdentity {
                writer_guid: writer_p.guid(),
                sequence_number: SequenceNumber::from(i64::from(id) + 1),
            };
            let options = WriteOptionsBuilder::new().related_sample_identity(related).build();
            writer.write_with_options(blob.clone(), options).expect("write");
        } else {
            writer.write(blob.clone(), None).expect("write");
        }
        let got = loop {
            match reader.take_next_sample() {
                Ok(Some(s)) if s.value().id == u32::MAX => {}
                Ok(Some(s)) => break s.into_value(),
                Ok(None) => {}
                Err(e) => panic!("read: {e:?}"),
            }
            assert!(start.elapsed() < limit, "sample {id} of {size} bytes did not arrive within {limit:?}");
            std::thread::sleep(Duration::from_millis(1));
        };
        assert!(got == blob, "sample {id} arrived changed");
        took.push(start.elapsed());
    }
    took
}

#[test]
fn a_sample_twenty_times_a_readers_socket_buffer_arrives_whole() {
    // 4 MB, about twice configs/ros2_lidar.toml's whole-window ESDF cloud:
    // most of its first burst overflows the reader's socket; the reader asks
    // for the rest (NACK_FRAG) and the writer repairs it in packed runs of
    // up to 64 KiB a round (at 8 fragments of 256 bytes a round, as RustDDS
    // 0.15.1 repairs, this takes over 15 s).
    let took = send_and_receive(171, 4_000_000, 3, false, Duration::from_secs(10));
    eprintln!("4 MB samples to a 208 KiB reader: {took:?}");
}

#[test]
fn fragmented_replies_with_a_request_id_arrive() {
    // Replies carry their request's identity as inline QoS: sizes around one
    // loopback datagram and well over it.
    for (i, size) in [60_000, 65_400, 65_480, 70_000, 1_000_000].into_iter().enumerate() {
        send_and_receive(172 + i as u16, size, 2, true, Duration::from_secs(5));
    }
}
