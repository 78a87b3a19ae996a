//! The player of `bench/node.sh`: publishes a recording that `edtmap
//! record` wrote to a running `edtmap node`, one frame as soon as the
//! previous one is mapped (the node's full rate), and measures, over DDS
//! on loopback:
//! - the latency from publishing a frame to receiving its ESDF cloud
//!   (matched by stamp);
//! - `get_distances` round trips for 1, 1,000 and 100,000 points (one
//!   call each), asked continuously from a second thread while the frames
//!   are mapped.
//!
//! Prints one JSON object.
//!
//!   node_player RECORDING.mcap SENSOR_TOPIC DOMAIN [FRAMES]

use edtmap_node::types::{
    CameraInfo, Dds, DiagnosticArray, GetDistancesRequest, GetDistancesResponse, Image, LaserScanMsg, Point,
    PointCloud2, TfMessage, TransformStamped,
};
use edtmap_ros::msg::Message;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile, ServiceMapping, ServiceTypeName,
};
use std::net::{IpAddr, Ipv4Addr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(500)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 20 })
}

fn context(domain: u16) -> Context {
    let p = DomainParticipantBuilder::new(domain)
        .with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)])
        .build()
        .expect("participant");
    Context::from_domain_participant(p).expect("context")
}

fn name(full: &str) -> Name {
    Name::parse(full).expect("name")
}

fn publisher<M: ros2_client::Message>(node: &mut Node, full: &str, pkg: &str, ty: &str) -> ros2_client::Publisher<M> {
    let t = node.create_topic(&name(full), MessageTypeName::new(pkg, ty), &qos()).expect("topic");
    node.create_publisher::<M>(&t, Some(qos())).expect("publisher")
}

fn subscription<M: ros2_client::Message + 'static>(
    node: &mut Node,
    full: &str,
    pkg: &str,
    ty: &str,
) -> ros2_client::Subscription<M> {
    let t = node.create_topic(&name(full), MessageTypeName::new(pkg, ty), &qos()).expect("topic");
    node.create_subscription::<M>(&t, Some(qos())).expect("subscription")
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// The round trip of one get_distances call for `points`.
fn ask(client: &ros2_client::Client<GetDistancesRequest, GetDistancesResponse>, points: &[Point]) -> Option<f64> {
    let start = Instant::now();
    let id = client.send_request(GetDistancesRequest { points: points.to_vec(), signed_distance: false }).ok()?;
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Ok(Some((rid, r))) = client.receive_response() {
            if rid == id {
                assert_eq!(r.distances.len(), points.len());
                return Some(start.elapsed().as_secs_f64() * 1e3);
            }
        }
        if Instant::now() > deadline {
            return None;
        }
        std::thread::sleep(Duration::from_micros(50));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: node_player RECORDING.mcap SENSOR_TOPIC DOMAIN [FRAMES]");
        std::process::exit(2);
    }
    let (path, sensor_topic, domain) = (&args[1], args[2].as_str(), args[3].parse::<u16>().expect("domain"));
    let max_frames: usize = args.get(4).map_or(usize::MAX, |f| f.parse().expect("frames"));
    let ctx = context(domain);
    let mut node = ctx
        .new_node(NodeName::new("/", "player").expect("name"), NodeOptions::new().enable_rosout(false))
        .expect("node");
    let parent = sensor_topic.rsplit_once('/').map_or("", |p| p.0);
    let clouds = publisher::<Dds<PointCloud2>>(&mut node, sensor_topic, "sensor_msgs", "PointCloud2");
    let images = publisher::<Dds<Image>>(&mut node, sensor_topic, "sensor_msgs", "Image");
    let infos = publisher::<Dds<CameraInfo>>(&mut node, &format!("{parent}/camera_info"), "sensor_msgs", "CameraInfo");
    let scans = publisher::<Dds<LaserScanMsg>>(&mut node, sensor_topic, "sensor_msgs", "LaserScan");
    let tf = publisher::<TfMessage>(&mut node, "/tf", "tf2_msgs", "TFMessage");
    let stats = subscription::<DiagnosticArray>(&mut node, "/edtmap/frame_stats", "diagnostic_msgs", "DiagnosticArray");
    let esdf = subscription::<Dds<PointCloud2>>(&mut node, "/edtmap/esdf_pointcloud", "sensor_msgs", "PointCloud2");

    // The recording, grouped by frame: its /tf, then camera info and sensor message.
    let reader = edtmap_ros::mcap::McapReader::open(std::path::Path::new(path)).expect("recording");
    let topics = ["/tf".to_string(), format!("{parent}/camera_info"), sensor_topic.to_string()];
    let mut frames: Vec<(i64, Vec<Message>)> = Vec::new();
    let mut pending = Vec::new();
    for raw in reader.messages(&topics) {
        let raw = raw.expect("message");
        let m = Message::decode(&raw.msg_type, &raw.data, raw.encoding).expect("decodes");
        let is_sensor = matches!(m, Message::PointCloud2(_) | Message::Image(_) | Message::LaserScan(_));
        pending.push(m);
        if is_sensor {
            frames.push((raw.log_time_ns as i64, std::mem::take(&mut pending)));
        }
    }
    frames.truncate(max_frames);

    // Queries from a second participant, continuously while mapping.
    let mapping = Arc::new(AtomicBool::new(true));
    let flag = mapping.clone();
    let queries = std::thread::spawn(move || {
        let ctx = context(domain);
        let mut node = ctx
            .new_node(NodeName::new("/", "planner").expect("name"), NodeOptions::new().enable_rosout(false))
            .expect("node");
        let client = node
            .create_client::<GetDistancesRequest, GetDistancesResponse>(
                ServiceMapping::Cyclone,
                &name("/edtmap/get_distances"),
                &ServiceTypeName::new("edtmap_msgs", "GetDistances"),
                qos(),
                qos(),
            )
            .expect("client");
        std::thread::sleep(Duration::from_secs(2));
        let points = |n: usize| {
            (0..n)
                .map(|i| Point {
                    x: (i % 97) as f64 * 0.1 - 4.8,
                    y: (i % 89) as f64 * 0.1 - 4.4,
                    z: (i % 23) as f64 * 0.1,
                })
                .collect::<Vec<_>>()
        };
        let sets = [(1usize, points(1)), (1000, points(1000)), (100_000, points(100_000))];
        let mut times: Vec<Vec<f64>> = vec![Vec::new(); 3];
        let mut lost = 0;
        while flag.load(Ordering::Relaxed) {
            for (k, (_, p)) in sets.iter().enumerate() {
                match ask(&client, p) {
                    Some(ms) => times[k].push(ms),
                    None => lost += 1,
                }
            }
        }
        (times, lost)
    });

    std::thread::sleep(Duration::from_secs(2));
    let publish = |m: &Message| match m.clone() {
        Message::PointCloud2(c) => clouds.publish(Dds(c)).expect("cloud"),
        Message::Image(i) => images.publish(Dds(i)).expect("image"),
        Message::CameraInfo(i) => infos.publish(Dds(i)).expect("info"),
        Message::LaserScan(s) => scans.publish(Dds(s)).expect("scan"),
        Message::Tf(ts) => {
            tf.publish(TfMessage { transforms: ts.iter().map(TransformStamped::from).collect() }).expect("tf")
        }
        _ => {}
    };
    let mut latencies = Vec::new();
    // The node's map and kept bytes after each frame.
    let mut memory: Vec<u64> = Vec::new();
    let value = |s: &DiagnosticArray, key: &str| {
        s.status
            .iter()
            .flat_map(|st| &st.values)
            .find(|kv| kv.key == key)
            .and_then(|kv| kv.value.parse::<u64>().ok())
            .unwrap_or(0)
    };
    let (mut mapped, mut lost_frames) = (0u64, 0u64);
    let start = Instant::now();
    for (stamp_ns, messages) in &frames {
        let sent = Instant::now();
        messages.iter().for_each(publish);
        let (mut got_cloud, mut got_stats) = (false, false);
        while !(got_cloud && got_stats) && sent.elapsed() < Duration::from_secs(10) {
            while let Ok(Some((c, _))) = esdf.take() {
                if c.0.header.stamp_ns == *stamp_ns {
                    latencies.push(sent.elapsed().as_secs_f64() * 1e3);
                    got_cloud = true;
                }
            }
            while let Ok(Some((s, _))) = stats.take() {
                if s.header.stamp_ns == *stamp_ns {
                    got_stats = true;
                    mapped += 1;
                    memory.push(value(&s, "map_bytes") + value(&s, "kept_bytes"));
                }
            }
            std::thread::sleep(Duration::from_micros(100));
        }
        if !got_stats {
            lost_frames += 1;
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    mapping.store(false, Ordering::Relaxed);
    let (mut times, lost_queries) = queries.join().expect("query thread");
    let q = |k: usize, t: &mut Vec<Vec<f64>>| {
        format!(
            "{{\"calls\": {}, \"median_ms\": {:.3}, \"p95_ms\": {:.3}}}",
            t[k].len(),
            percentile(&mut t[k], 0.5),
            percentile(&mut t[k], 0.95)
        )
    };
    let at = |f: f64| memory.get(((memory.len().max(1) - 1) as f64 * f) as usize).copied().unwrap_or(0);
    let memory_json = format!("[{}, {}, {}, {}]", at(0.25), at(0.5), at(0.75), at(1.0));
    println!(
        "{{\"map_bytes_quartiles\": {memory_json}, \"frames\": {}, \"mapped\": {mapped}, \"lost_frames\": {lost_frames}, \"rate_hz\": {:.2}, \"esdf_latency_median_ms\": {:.2}, \"esdf_latency_p95_ms\": {:.2}, \"get_distances_1\": {}, \"get_distances_1000\": {}, \"get_distances_100000\": {}, \"lost_queries\": {lost_queries}}}",
        frames.len(),
        mapped as f64 / elapsed,
        percentile(&mut latencies.clone(), 0.5),
        percentile(&mut latencies, 0.95),
        q(0, &mut times),
        q(1, &mut times),
        q(2, &mut times)
    );
}
