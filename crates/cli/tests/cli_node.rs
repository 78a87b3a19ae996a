//! `edtmap node` end to end over DDS on loopback: a recording that `edtmap
//! record` wrote is published frame by frame by a second ROS 2 participant
//! (`ros2-client`, in this test's process), the node maps it live, its
//! services answer, and on SIGINT it saves a map byte-identical to the one
//! `edtmap run` makes of the same recording.

mod common;

use common::{bin, finish, run_in};
use edtmap_node::types::{
    CameraInfo, Dds, DiagnosticArray, GetDistancesRequest, GetDistancesResponse, GetEsdfBoxRequest, GetEsdfBoxResponse,
    Image, LaserScanMsg, Point, PointCloud2, TfMessage, TransformStamped,
};
use edtmap_ros::msg::Message;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, QosProfile, ServiceMapping, ServiceTypeName};
use std::net::{IpAddr, Ipv4Addr};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

const MIN: Duration = Duration::from_secs(60);

/// Reliable, keeping more samples than a flood publishes at once (a KEEP_LAST
/// writer drops its oldest samples, sent or not, beyond its depth).
fn qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(500)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 64 })
}

/// Waits up to `limit` for `f` to give something.
fn wait<T>(limit: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if let Some(t) = f() {
            return Some(t);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    None
}

fn frames_in(stats: &DiagnosticArray) -> u64 {
    stats
        .status
        .iter()
        .flat_map(|s| &s.values)
        .find(|kv| kv.key == "frames")
        .and_then(|kv| kv.value.parse().ok())
        .unwrap_or(0)
}

/// Records with `record_args` (writing `rec.mcap` and `rec.toml`) and
/// replays the recording with `edtmap run` in `d`.
fn record_and_replay(d: &Path, record_args: &[&str]) {
    let rec = run_in(d, &[&["record"], record_args, &["rec.mcap"]].concat(), MIN);
    assert_eq!(rec.code(), Some(0), "{}", rec.stderr);
    let replay = run_in(
        d,
        &["run", "--config", "rec.toml", "--dataset", "rec.mcap", "--out", "replay", "--save", "replay.edtmap"],
        MIN,
    );
    assert_eq!(replay.code(), Some(0), "{}", replay.stderr);
}

/// Runs a node in `d` on `config` (the recording's, perhaps edited) with
/// `ros` as its `[ros]` section, on a DDS domain of its own (`salt`
/// apart from the other tests'), while `publish` feeds it, stops it with SIGINT (it saves its map and
/// exits), and checks that it mapped `frames` frames into the replay's
/// map, byte for byte. Returns the node's run.
fn live_map_equals_replay(
    d: &Path,
    what: &str,
    salt: u32,
    config: &str,
    ros: &str,
    frames: u64,
    publish: impl FnOnce(u16),
) -> common::Run {
    let domain = 100 + (std::process::id() + salt) % 100;
    let config = format!("{config}\n[ros]\n{ros}localhost_only = true\npose_wait_s = 5.0\n");
    std::fs::write(d.join("node.toml"), config).expect("write config");
    let mut cmd = bin();
    cmd.args(["-v", "node", "--config", "node.toml", "--save", "node.edtmap"])
        .current_dir(d)
        .env("ROS_DOMAIN_ID", domain.to_string());
    let child =
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the node starts");
    let pid = child.id();
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| publish(domain as u16)));
    // SIGINT: the node saves its map and exits.
    // SAFETY: kill on our own child's pid.
    unsafe { libc::kill(pid as libc::pid_t, libc::SIGINT) };
    let run = finish(child, MIN);
    if let Err(e) = outcome {
        panic!("{what}: {:?}\nnode stdout:\n{}\nnode stderr:\n{}", e.downcast_ref::<String>(), run.stdout, run.stderr);
    }
    assert_eq!(run.code(), Some(0), "{}\n{}", run.stdout, run.stderr);
    assert!(run.stdout.contains(&format!("{frames} frames integrated")), "{}", run.stdout);
    let (live, replayed) = (
        std::fs::read(d.join("node.edtmap")).expect("node map"),
        std::fs::read(d.join("replay.edtmap")).expect("replay map"),
    );
    assert!(
        live == replayed,
        "{what}: the live map differs from the replay's ({} and {} bytes)",
        live.len(),
        replayed.len()
    );
    run
}

/// Records `scene`, replays it with `edtmap run`, publishes it to a node
/// frame by frame, and checks the node against the replay.
fn live_equals_replay(scene: &str, frames: u64, sensor_topic: &str, edit: fn(String) -> String) {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    record_and_replay(d, &["--scene", scene, "--frames", &frames.to_string()]);
    // The node's config: the recording's, with [ros] for the live topics.
    let config = edit(std::fs::read_to_string(d.join("rec.toml")).expect("config"));
    let ros = format!(
        "sensor_topic = \"{sensor_topic}\"\npose_topic = \"/tf\"\nworld_frame = \"map\"\nesdf_pointcloud_hz = 100.0\n"
    );
    live_map_equals_replay(d, scene, scene.len() as u32 * 7, &config, &ros, frames, |domain| {
        drive(d, domain, frames, sensor_topic)
    });
}

#[test]
fn a_published_point_cloud_recording_maps_like_its_replay_and_the_services_answer_as_its_map() {
    live_equals_replay("uav_pillars", 6, "/points", |c| c);
}

#[test]
fn a_published_depth_image_recording_maps_like_its_replay_with_the_camera_infos_intrinsics() {
    // The node's [sensor] says other intrinsics: the camera info's win, as
    // they do in the replay.
    live_equals_replay("room", 4, "/camera/depth/image", |c| {
        let fx = c.lines().find(|l| l.starts_with("fx = ")).expect("fx").to_string();
        c.replace(&fx, "fx = 111.0")
    });
}

#[test]
fn a_published_laser_scan_recording_maps_like_its_replay() {
    live_equals_replay("planar", 6, "/scan", |c| c);
}

/// A ROS 2 node named `name` of its own participant in `domain`, on loopback.
fn test_node(domain: u16, name: &str) -> ros2_client::Node {
    let participant = DomainParticipantBuilder::new(domain)
        .with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)])
        .build()
        .expect("participant");
    let context = Context::from_domain_participant(participant).expect("context");
    context.new_node(NodeName::new("/", name).expect("name"), NodeOptions::new().enable_rosout(false)).expect("node")
}

/// The topic `ns/base` of type `pkg/ty`, with [`qos`].
fn topic(node: &mut ros2_client::Node, ns: &str, base: &str, pkg: &str, ty: &str) -> ros2_client::dds::rustdds::Topic {
    node.create_topic(&Name::new(ns, base).expect("name"), MessageTypeName::new(pkg, ty), &qos()).expect("topic")
}

/// A publisher on [`topic`].
fn publisher<M: serde::Serialize>(
    node: &mut ros2_client::Node,
    ns: &str,
    base: &str,
    pkg: &str,
    ty: &str,
) -> ros2_client::Publisher<M> {
    let t = topic(node, ns, base, pkg, ty);
    node.create_publisher::<M>(&t, Some(qos())).expect("publisher")
}

/// The node's `frame_stats`.
fn frame_stats(node: &mut ros2_client::Node) -> ros2_client::Subscription<DiagnosticArray> {
    let t = topic(node, "/edtmap", "frame_stats", "diagnostic_msgs", "DiagnosticArray");
    node.create_subscription::<DiagnosticArray>(&t, Some(qos())).expect("subscription")
}

/// Publishes the recording to the node and checks what it answers.
fn drive(d: &Path, domain: u16, frames: u64, sensor_topic: &str) {
    let mut node = test_node(domain, "player");
    let sensor_name = sensor_topic.trim_start_matches('/');
    let (ns, base) = match sensor_name.rsplit_once('/') {
        Some((ns, base)) => (format!("/{ns}"), base.to_string()),
        None => ("/".to_string(), sensor_name.to_string()),
    };
    let clouds = publisher::<Dds<PointCloud2>>(&mut node, &ns, &base, "sensor_msgs", "PointCloud2");
    let images = publisher::<Dds<Image>>(&mut node, &ns, &base, "sensor_msgs", "Image");
    let infos = publisher::<Dds<CameraInfo>>(&mut node, &ns, "camera_info", "sensor_msgs", "CameraInfo");
    let scans = publisher::<Dds<LaserScanMsg>>(&mut node, &ns, &base, "sensor_msgs", "LaserScan");
    let tf = publisher::<TfMessage>(&mut node, "/", "tf", "tf2_msgs", "TFMessage");
    let stats = frame_stats(&mut node);
    let t = topic(&mut node, "/edtmap", "esdf_pointcloud", "sensor_msgs", "PointCloud2");
    let esdf = node.create_subscription::<Dds<PointCloud2>>(&t, Some(qos())).expect("subscription");
    let srv = |base: &str| Name::new("/edtmap", base).expect("name");
    let distances = node
        .create_client::<GetDistancesRequest, GetDistancesResponse>(
            ServiceMapping::Cyclone,
            &srv("get_distances"),
            &ServiceTypeName::new("edtmap_msgs", "GetDistances"),
            qos(),
            qos(),
        )
        .expect("client");
    let boxes = node
        .create_client::<GetEsdfBoxRequest, GetEsdfBoxResponse>(
            ServiceMapping::Cyclone,
            &srv("get_esdf_box"),
            &ServiceTypeName::new("edtmap_msgs", "GetEsdfBox"),
            qos(),
            qos(),
        )
        .expect("client");
    // The same service asked as a Fast DDS client asks (the request id in
    // the RTPS sample identity; the reply carries it as inline QoS).
    let distances_enhanced = node
        .create_client::<GetDistancesRequest, GetDistancesResponse>(
            ServiceMapping::Enhanced,
            &srv("get_distances"),
            &ServiceTypeName::new("edtmap_msgs", "GetDistances"),
            qos(),
            qos(),
        )
        .expect("client");

    // The recording's poses (/tf) and clouds, in order.
    let reader = edtmap_ros::mcap::McapReader::open(&d.join("rec.mcap")).expect("recording");
    let topics = ["/tf".to_string(), format!("/{ns}/camera_info").replace("//", "/"), sensor_topic.to_string()];
    let mut by_frame: Vec<(TfMessage, Vec<Message>)> = Vec::new();
    let mut pending_tf = None;
    let mut pending = Vec::new();
    for raw in reader.messages(&topics) {
        let raw = raw.expect("message");
        match Message::decode(&raw.msg_type, &raw.data, raw.encoding).expect("decodes") {
            Message::Tf(ts) => {
                pending_tf = Some(TfMessage { transforms: ts.iter().map(TransformStamped::from).collect() })
            }
            m @ Message::CameraInfo(_) => pending.push(m),
            m => {
                pending.push(m);
                by_frame.push((pending_tf.take().expect("a pose before each frame"), std::mem::take(&mut pending)));
            }
        }
    }
    let publish = |m: &Message| match m.clone() {
        Message::PointCloud2(c) => clouds.publish(Dds(c)).expect("cloud"),
        Message::Image(i) => images.publish(Dds(i)).expect("image"),
        Message::CameraInfo(i) => infos.publish(Dds(i)).expect("camera info"),
        Message::LaserScan(s) => scans.publish(Dds(s)).expect("scan"),
        other => panic!("unexpected {}", other.type_name()),
    };
    assert_eq!(by_frame.len() as u64, frames);
    // Each frame's stamp, which the node's clouds after it carry.
    let stamp_of = |m: &Message| match m {
        Message::PointCloud2(c) => Some(c.header.stamp_ns),
        Message::Image(i) => Some(i.header.stamp_ns),
        Message::LaserScan(s) => Some(s.header.stamp_ns),
        _ => None,
    };
    let stamps: Vec<i64> =
        by_frame.iter().map(|(_, ms)| ms.iter().find_map(stamp_of).expect("a stamped sensor message")).collect();

    // Discovery on loopback: give both participants a moment, then send
    // each frame once its predecessor is mapped (paced: nothing drops).
    std::thread::sleep(Duration::from_secs(2));
    let mut mapped = 0;
    let mut last_esdf = None;
    for (i, (pose, sensor)) in by_frame.into_iter().enumerate() {
        let want = i as u64 + 1;
        let mut tries = 0;
        while mapped < want {
            // A frame lost to discovery not yet done is sent again; one
            // that arrived is never sent twice (the node counts it first).
            assert!(tries < 5, "frame {i} was not mapped");
            tf.publish(pose.clone()).expect("tf");
            sensor.iter().for_each(publish);
            tries += 1;
            let got = wait(Duration::from_secs(10), || match stats.take() {
                Ok(s) => s.map(|(s, _)| frames_in(&s)).filter(|&n| n >= want),
                Err(e) => panic!("frame_stats: {e:?}"),
            });
            if let Some(n) = got {
                mapped = n;
            }
        }
        while let Ok(Some((c, _))) = esdf.take() {
            last_esdf = Some(c);
        }
    }
    assert_eq!(mapped, frames);
    // The node publishes a cloud after each frame it maps: the last frame's
    // may still be on its way, or dropped by the reader's socket when the
    // clouds come faster than it drains them. Wait a while for it; the
    // cloud checked is the last one that came, against the replay of the
    // frames up to the one it carries the stamp of.
    let frame_of = |c: &Dds<PointCloud2>| stamps.iter().position(|&s| (s - c.0.header.stamp_ns).abs() < 1000);
    let last = stamps.len() - 1;
    let until = std::time::Instant::now() + Duration::from_secs(5);
    while std::time::Instant::now() < until && last_esdf.as_ref().and_then(frame_of) != Some(last) {
        match esdf.take() {
            Ok(Some((c, _))) => last_esdf = Some(c),
            _ => std::thread::sleep(Duration::from_millis(10)),
        }
    }

    // The replay's map answers the same queries bit for bit.
    let map = edtmap::load_map(&d.join("replay.edtmap")).expect("replay map");
    let cloud = last_esdf.expect("an ESDF cloud came");
    let partial;
    let cloud_map = match frame_of(&cloud).expect("the cloud carries a frame's stamp") {
        k if k == last => &map,
        k => {
            let n = (k + 1).to_string();
            let part = run_in(
                d,
                &[
                    "run",
                    "--config",
                    "rec.toml",
                    "--dataset",
                    "rec.mcap",
                    "--frames",
                    &n,
                    "--out",
                    "part",
                    "--save",
                    "part.edtmap",
                ],
                MIN,
            );
            assert_eq!(part.code(), Some(0), "{}", part.stderr);
            partial = edtmap::load_map(&d.join("part.edtmap")).expect("partial replay map");
            &partial
        }
    };
    let values: Vec<f32> = cloud.0.data.chunks(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    // Points near the mapped voxels (off their centres, so gradients
    // interpolate), and some far from anything.
    let mut query: Vec<Point> = values
        .chunks(4)
        .step_by(7)
        .take(300)
        .map(|p| Point { x: f64::from(p[0]) + 0.031, y: f64::from(p[1]) - 0.047, z: f64::from(p[2]) + 0.012 })
        .collect();
    query.extend((0..50).map(|i| Point { x: 1e3 + f64::from(i), y: -7.0, z: f64::NAN.min(1.0) }));
    // Then enough points that the reply (34 bytes a point, 3.4 MB) spans
    // many loopback datagrams: a seeded walk over the mapped region.
    let mut rng = 0x9e37_79b9_7f4a_7c15_u64;
    let mut unit = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let (lo_b, hi_b) = map.occupancy().key_bounds().expect("a mapped box");
    let side = f64::from(edtmap::BLOCK_SIDE) * map.voxel_size_m();
    let (lo_m, hi_m) = (lo_b.map(|b| f64::from(b) * side), hi_b.map(|b| f64::from(b + 1) * side));
    query.extend((0..99_650).map(|_| {
        let at = |k: usize, u: f64| lo_m[k] + u * (hi_m[k] - lo_m[k]);
        Point { x: at(0, unit()), y: at(1, unit()), z: at(2, unit()) }
    }));
    let req = GetDistancesRequest { points: query.clone(), signed_distance: false };
    let id = distances.send_request(req.clone()).expect("request");
    let resp = wait(Duration::from_secs(20), || {
        distances.receive_response().ok().flatten().filter(|(rid, _)| *rid == id).map(|(_, r)| r)
    })
    .expect("get_distances answers");
    let id = distances_enhanced.send_request(req).expect("request");
    let resp_enhanced = wait(Duration::from_secs(20), || {
        distances_enhanced.receive_response().ok().flatten().filter(|(rid, _)| *rid == id).map(|(_, r)| r)
    })
    .expect("get_distances answers a Fast DDS-style client");
    let bits = |r: &GetDistancesResponse| r.distances.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&resp_enhanced), bits(&resp), "both request layouts get the same distances");
    assert_eq!((&resp_enhanced.gradients, &resp_enhanced.states), (&resp.gradients, &resp.states));
    let want = edtmap::query::distances(&map, &query.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(), false);
    assert!(resp.success, "{}", resp.message);
    assert_eq!(resp.distances.len(), want.len());
    for (i, w) in want.iter().enumerate() {
        let same = resp.distances[i].to_bits() == w.distance_m.to_bits()
            || (resp.distances[i].is_nan() && w.distance_m.is_nan());
        assert!(same, "point {i}: {} vs {}", resp.distances[i], w.distance_m);
        assert_eq!([resp.gradients[i].x, resp.gradients[i].y, resp.gradients[i].z], w.gradient, "point {i}");
        assert_eq!(resp.states[i], w.state as u8, "point {i}");
    }
    assert!(want.iter().filter(|w| w.distance_m < 1.0).count() > 100, "the queries reach mapped space");
    assert!(resp.states[300..350].iter().all(|&s| s == edtmap::PointState::Outside as u8));

    // 40 x 40 x 40 voxels: a 1.1 MB reply.
    let vs = map.voxel_size_m();
    let (lo, hi) = ([-20.0 * vs, -20.0 * vs, -10.0 * vs], [20.0 * vs, 20.0 * vs, 30.0 * vs]);
    let req = GetEsdfBoxRequest {
        min_corner: Point { x: lo[0], y: lo[1], z: lo[2] },
        max_corner: Point { x: hi[0], y: hi[1], z: hi[2] },
        signed_distance: false,
    };
    let id = boxes.send_request(req).expect("request");
    let resp = wait(Duration::from_secs(20), || match boxes.receive_response() {
        Ok(r) => r.filter(|(rid, _)| *rid == id).map(|(_, r)| r),
        Err(e) => panic!("get_esdf_box: {e:?}"),
    })
    .expect("get_esdf_box answers");
    let want = edtmap::query::distance_box(&map, lo, hi, false).expect("box");
    assert!(resp.success, "{}", resp.message);
    assert_eq!(resp.size, want.dims.map(|d| d as u32));
    assert_eq!(resp.distances, want.distance_m);
    assert_eq!(resp.states, want.state);
    assert_eq!(resp.gradients.len(), 3 * want.distance_m.len());

    // The ESDF cloud: every point's distance is the map's at that voxel.
    assert_eq!(cloud.0.point_step, 16);
    assert!(cloud.0.width > 100, "{} points", cloud.0.width);
    for p in values.chunks(4) {
        let at = [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])];
        let v = edtmap::VoxelIndex::containing(at, map.voxel_size_m()).expect("finite");
        let (dist, saturated) = edtmap::query::voxel_distance(cloud_map, v, false);
        assert!(!saturated && dist as f32 == p[3], "{p:?} vs {dist}");
    }
}

/// The numbers of the node's closing line: integrated, received, dropped,
/// skipped.
fn closing_numbers(stdout: &str) -> [u64; 4] {
    let line = stdout.lines().find(|l| l.starts_with("edtmap node stopped")).expect("closing line");
    let nums: Vec<u64> =
        line.split(|c: char| !c.is_ascii_digit()).filter(|s| !s.is_empty()).filter_map(|s| s.parse().ok()).collect();
    [nums[0], nums[1], nums[2], nums[3]]
}

/// Runs a node on a recording of `frames` frames of uav_pillars published
/// all at once, then bad messages ([`flood`]); `extra` is added to its
/// `[ros]`. Returns the node's run and its saved map.
fn flooded_node(d: &Path, frames: usize, extra: &str, salt: u32) -> (common::Run, edtmap::GlobalMap) {
    let rec = run_in(d, &["record", "--scene", "uav_pillars", "--frames", &frames.to_string(), "rec.mcap"], MIN);
    assert_eq!(rec.code(), Some(0), "{}", rec.stderr);
    let domain = 100 + (std::process::id() + salt) % 100;
    let mut config = std::fs::read_to_string(d.join("rec.toml")).expect("config");
    config.push_str("\n[ros]\nsensor_topic = \"/points\"\npose_topic = \"/tf\"\nworld_frame = \"map\"\nlocalhost_only = true\npose_wait_s = 0.3\n");
    config.push_str(extra);
    std::fs::write(d.join("node.toml"), config).expect("write config");
    let mut cmd = bin();
    cmd.args(["node", "--config", "node.toml", "--save", "node.edtmap"])
        .current_dir(d)
        .env("ROS_DOMAIN_ID", domain.to_string());
    let child =
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the node starts");
    let pid = child.id();
    let outcome = std::panic::catch_unwind(|| flood(d, domain as u16));
    std::thread::sleep(Duration::from_secs(1));
    // SAFETY: kill on our own child's pid.
    unsafe { libc::kill(pid as libc::pid_t, libc::SIGINT) };
    let run = finish(child, MIN);
    if let Err(e) = outcome {
        panic!("{:?}\nnode stderr:\n{}", e.downcast_ref::<String>(), run.stderr);
    }
    assert_eq!(run.code(), Some(0), "{}\n{}", run.stdout, run.stderr);
    let map = edtmap::load_map(&d.join("node.edtmap")).expect("saved map");
    (run, map)
}

#[test]
fn a_flood_drops_frames_and_bad_messages_are_skipped_by_kind_keeping_the_map() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (run, map) = flooded_node(dir.path(), 20, "", 41);
    let [integrated, received, dropped, skipped] = closing_numbers(&run.stdout);
    // 20 frames at once (a best-effort subscription may lose some to a full
    // socket buffer), then 3 bad messages and one cloud whose frame has no
    // transform: every message received is accounted for.
    assert!((8..=24).contains(&received), "{}", run.stdout);
    assert!(integrated >= 1 && dropped >= 1, "a flood drops frames: {}", run.stdout);
    assert_eq!(skipped, 4, "{}\n{}", run.stdout, run.stderr);
    assert_eq!(integrated + dropped + skipped, received, "{}", run.stdout);
    // Each malformation is its own kind, counted and logged once with its own description.
    let kinds = [
        "bad message: PointCloud2 point_step < its fields",
        "bad message: PointCloud2 data shorter than its points",
        "bad message: PointCloud2 without x, y or z",
    ];
    for kind in kinds {
        assert!(run.stdout.contains(&format!("\"{kind}\": 1")), "{kind}: {}", run.stdout);
        assert_eq!(run.stderr.matches(&format!("({kind};")).count(), 1, "{kind}: {}", run.stderr);
    }
    assert!(run.stdout.contains("\"missing transform\": 1"), "{}", run.stdout);
    // What was mapped is kept and saved.
    assert!(map.occupancy().len() > 10);
}

#[test]
fn map_clearing_bounds_the_map_and_keeps_its_edt_exact() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, full) = flooded_node(&subdir(dir.path(), "full"), 30, "", 53);
    let cleared_dir = subdir(dir.path(), "cleared");
    let (_, cleared) = flooded_node(
        &cleared_dir,
        30,
        "map_clearing_radius_m = 3.0\nmap_clearing_period_s = 0.01\nmap_clearing_save = \"before_clearing.edtmap\"\n",
        67,
    );
    // What was forgotten was saved first: the last save holds more than the map kept.
    let saved = edtmap::load_map(&cleared_dir.join("before_clearing.edtmap")).expect("saved before clearing");
    assert!(
        saved.occupancy().len() > cleared.occupancy().len(),
        "{} saved, {} kept",
        saved.occupancy().len(),
        cleared.occupancy().len()
    );
    // A ball of 3 m holds at most (4/3)π(3 + 1.4)³ / 1.6³ ≈ 87 blocks of 1.6 m.
    assert!(
        cleared.occupancy().len() <= 87 && full.occupancy().len() > 2 * cleared.occupancy().len(),
        "{} blocks cleared, {} without",
        cleared.occupancy().len(),
        full.occupancy().len()
    );
    let errors =
        edtmap::eval::edt_errors(&cleared, &edtmap::eval::edt_extent(&cleared).expect("an EDT")).expect("exact EDT");
    assert!(errors.max_m == 0.0 && errors.wrong_fraction == 0.0, "{errors:?}");
}

/// The folder `name` in `dir`, made.
fn subdir(dir: &Path, name: &str) -> std::path::PathBuf {
    let sub = dir.join(name);
    std::fs::create_dir_all(&sub).expect("mkdir");
    sub
}

/// Publishes the whole recording at once, then bad messages.
fn flood(d: &Path, domain: u16) {
    let mut node = test_node(domain, "flood");
    let points = publisher::<Dds<PointCloud2>>(&mut node, "/", "points", "sensor_msgs", "PointCloud2");
    let tf = publisher::<TfMessage>(&mut node, "/", "tf", "tf2_msgs", "TFMessage");
    let stats = frame_stats(&mut node);
    let reader = edtmap_ros::mcap::McapReader::open(&d.join("rec.mcap")).expect("recording");
    let topics = ["/tf".to_string(), "/points".to_string()];
    let mut messages = Vec::new();
    for raw in reader.messages(&topics) {
        let raw = raw.expect("message");
        messages.push(Message::decode(&raw.msg_type, &raw.data, raw.encoding).expect("decodes"));
    }
    std::thread::sleep(Duration::from_secs(2));
    let mut last_cloud = None;
    for m in messages {
        match m {
            Message::Tf(ts) => {
                tf.publish(TfMessage { transforms: ts.iter().map(TransformStamped::from).collect() }).expect("tf")
            }
            Message::PointCloud2(c) => {
                last_cloud = Some(c.clone());
                points.publish(Dds(c)).expect("cloud");
            }
            _ => {}
        }
    }
    wait(Duration::from_secs(20), || stats.take().ok().flatten()).expect("the node maps");
    let good = last_cloud.expect("a cloud");
    let mut bad_step = good.clone();
    bad_step.point_step = 7;
    let mut truncated = good.clone();
    truncated.data.truncate(truncated.data.len() / 2);
    let mut no_fields = good.clone();
    no_fields.fields.clear();
    let mut elsewhere = good;
    elsewhere.header.frame_id = "no_such_frame".into();
    for c in [bad_step, truncated, no_fields, elsewhere] {
        points.publish(Dds(c)).expect("cloud");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A two-sensor robot (`configs/ugv_corridor_camera.toml`'s LiDAR and depth
/// camera) recorded, replayed with `edtmap run`, and published to a node
/// message by message in the recording's order, each sensor frame once
/// the one before it is mapped: the node subscribes to both sensors'
/// topics and saves the replay's map, byte for byte.
#[test]
fn a_published_two_sensor_recording_maps_like_its_replay() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let two = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/ugv_corridor_camera.toml");
    let frames = 3u64;
    record_and_replay(d, &["--config", two.to_str().expect("utf-8"), "--frames", &frames.to_string()]);
    // Poses from /tf (map → base_link), the mounts from the [[sensors]] entries.
    let ros = "pose_topic = \"/tf\"\nworld_frame = \"map\"\nbody_frame = \"base_link\"\n";
    let config = std::fs::read_to_string(d.join("rec.toml")).expect("config");
    let run = live_map_equals_replay(d, "two sensors", 97, &config, ros, 2 * frames, |domain| {
        publish_each_frame(d, domain, 2 * frames)
    });
    for (name, topic) in [("lidar_top", "/lidar_top/points"), ("front_camera", "/front_camera/depth/image")] {
        let line = format!("{name} on {topic}: {frames} frames integrated of {frames} received, 0 dropped");
        assert!(run.stdout.contains(&line), "{line}\n{}", run.stdout);
    }
}

/// Publishes `rec.mcap`'s `/tf`, point clouds, depth images and camera
/// infos in its order, each sensor message once the node has mapped the
/// one before it (sent again if discovery lost it), until `frames` are mapped.
fn publish_each_frame(d: &Path, domain: u16, frames: u64) {
    let mut node = test_node(domain, "player");
    let clouds = publisher::<Dds<PointCloud2>>(&mut node, "/lidar_top", "points", "sensor_msgs", "PointCloud2");
    let camera = "/front_camera/depth";
    let images = publisher::<Dds<Image>>(&mut node, camera, "image", "sensor_msgs", "Image");
    let infos = publisher::<Dds<CameraInfo>>(&mut node, camera, "camera_info", "sensor_msgs", "CameraInfo");
    let tf = publisher::<TfMessage>(&mut node, "/", "tf", "tf2_msgs", "TFMessage");
    let stats = frame_stats(&mut node);

    let reader = edtmap_ros::mcap::McapReader::open(&d.join("rec.mcap")).expect("recording");
    let topics: Vec<String> =
        ["/tf", "/lidar_top/points", "/front_camera/depth/camera_info", "/front_camera/depth/image"]
            .map(String::from)
            .to_vec();
    // Each sensor message with the pose and camera info before it.
    let mut steps: Vec<(TfMessage, Vec<Message>)> = Vec::new();
    let (mut pose, mut before) = (None, Vec::new());
    for raw in reader.messages(&topics) {
        let raw = raw.expect("message");
        match Message::decode(&raw.msg_type, &raw.data, raw.encoding).expect("decodes") {
            Message::Tf(ts) => pose = Some(TfMessage { transforms: ts.iter().map(TransformStamped::from).collect() }),
            m @ Message::CameraInfo(_) => before.push(m),
            m => {
                before.push(m);
                steps.push((pose.clone().expect("a pose first"), std::mem::take(&mut before)));
            }
        }
    }
    assert_eq!(steps.len() as u64, frames);
    std::thread::sleep(Duration::from_secs(2));
    let mut mapped = 0;
    for (i, (pose, messages)) in steps.into_iter().enumerate() {
        let want = i as u64 + 1;
        let mut tries = 0;
        while mapped < want {
            assert!(tries < 5, "frame {i} was not mapped");
            tf.publish(pose.clone()).expect("tf");
            for m in &messages {
                match m.clone() {
                    Message::PointCloud2(c) => clouds.publish(Dds(c)).expect("cloud"),
                    Message::Image(im) => images.publish(Dds(im)).expect("image"),
                    Message::CameraInfo(c) => infos.publish(Dds(c)).expect("camera info"),
                    other => panic!("unexpected {}", other.type_name()),
                }
            }
            tries += 1;
            if let Some(n) = wait(Duration::from_secs(10), || match stats.take() {
                Ok(s) => s.map(|(s, _)| frames_in(&s)).filter(|&n| n >= want),
                Err(e) => panic!("frame_stats: {e:?}"),
            }) {
                mapped = n;
            }
        }
    }
    assert_eq!(mapped, frames);
}
