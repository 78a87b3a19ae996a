//! `edtmap node`: the mapper live on ROS 2, over DDS in pure Rust
//! (`ros2-client` and RustDDS; no ROS installation).
//!
//! Three threads share the work:
//! - **input** takes the sensor, pose and camera-info messages as they
//!   arrive, waits for each sensor message's pose ([`live`]), and leaves
//!   the frame in a one-place slot: when frames come faster than they are
//!   mapped, the newest wins and the one it replaces is counted as dropped;
//! - **mapping** integrates the slot's frame, then hands the queries a new
//!   snapshot of the map (a copy-on-write clone: one pointer per block) and
//!   publishes the outputs due at their rates;
//! - **services** answer `get_distances`, `get_esdf_box` and `save_map`
//!   from the latest snapshot, so a query never waits for a frame.
//!
//! A message that cannot be used (bad layout, unknown encoding, no pose in
//! time) is skipped and counted by kind, with a warning the first time of
//! each kind; nothing mapped is lost.

pub mod config;
mod live;
mod outputs;
mod rpc;
mod services;
pub mod types;

pub use services::{QueryLimits, MAX_BOX_VOXELS, MAX_QUERY_POINTS};

use config::{Intrinsics, OccupiedScope, PoseType, RosSection, ServiceMapping};
use edtmap::config::{Config, SensorKind};
use edtmap::cpu::CpuBackend;
use edtmap::sensor::Frame;
use edtmap::{GlobalMap, MapError, Mapper, SharedMapper};
use edtmap_ros::msg::{CameraInfo, Message};
use edtmap_ros::poses::SensorMessage;
use edtmap_ros::RosOptions;
use live::{LiveFrames, Skipped};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile, Subscription};
use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use types::{Dds, Time};

/// Why the node could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The config does not fit a live node.
    #[error("[ros] {0}")]
    Config(String),
    /// The mapper refused the config, or failed.
    #[error(transparent)]
    Map(#[from] MapError),
    /// DDS could not create an entity (a port in use, a bad name).
    #[error("ROS 2 (DDS): {0}")]
    Dds(String),
}

/// The map as the queries see it (the facade's [`edtmap::Snapshot`]).
pub use edtmap::Snapshot;

/// Counters of a running node.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Sensor messages received.
    pub received: u64,
    /// Frames integrated.
    pub integrated: u64,
    /// Frames replaced in the slot by a newer one before they were mapped.
    pub dropped: u64,
    /// Messages skipped, by kind (`bad message`, `missing transform`,
    /// `bad pose`, `pose queue full`, `mapper refused`, `bad request`).
    pub skipped: BTreeMap<String, u64>,
    /// Service requests answered.
    pub requests: u64,
}

/// The frame outputs are labelled with before any pose said otherwise.
const DEFAULT_WORLD_FRAME: &str = "map";

/// What the threads share.
struct Shared {
    stop: AtomicBool,
    /// The newest frame not yet mapped, with the depth camera's latest info
    /// and the fixed frame its pose is in.
    slot: Mutex<Option<(Frame, Option<CameraInfo>, String)>>,
    wake: Condvar,
    /// The mapper (locked by the mapping thread) and the snapshot the
    /// services read.
    mapper: SharedMapper<CpuBackend>,
    received: AtomicU64,
    integrated: AtomicU64,
    dropped: AtomicU64,
    requests: AtomicU64,
    skipped: Mutex<BTreeMap<String, u64>>,
}

impl Shared {
    fn skip(&self, s: &Skipped) {
        let mut counts = self.skipped.lock().unwrap_or_else(PoisonError::into_inner);
        let n = counts.entry(s.kind.to_string()).or_insert(0);
        *n += 1;
        if *n == 1 {
            tracing::warn!(
                "skipping a message ({}; later ones of this kind are counted, not logged): {}",
                s.kind,
                s.reason
            );
        } else {
            tracing::debug!("skipping a message ({}): {}", s.kind, s.reason);
        }
    }

    fn snapshot(&self) -> Arc<Snapshot> {
        self.mapper.snapshot()
    }

    fn stats(&self) -> NodeStats {
        NodeStats {
            received: self.received.load(Relaxed),
            integrated: self.integrated.load(Relaxed),
            dropped: self.dropped.load(Relaxed),
            skipped: self.skipped.lock().unwrap_or_else(PoisonError::into_inner).clone(),
            requests: self.requests.load(Relaxed),
        }
    }
}

/// A running node; [`NodeHandle::stop`] ends it.
pub struct NodeHandle {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    mapping: Option<JoinHandle<Result<(), NodeError>>>,
    save_on_exit: Option<PathBuf>,
    // Dropped last: the DDS entities live in the threads.
    _node: Arc<Mutex<Node>>,
}

impl std::fmt::Debug for NodeHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeHandle").field("stats", &self.shared.stats()).finish_non_exhaustive()
    }
}

/// QoS of sensor subscriptions: best effort, so they match best-effort and
/// reliable drivers alike.
fn sensor_qos() -> QosProfile {
    QosProfile::subscription_default().history(History::KeepLast { depth: 5 })
}

/// QoS of pose subscriptions: best effort (a best-effort reader matches
/// best-effort and reliable writers; odometry drivers often publish best
/// effort), keeping `depth` samples.
fn pose_qos(depth: usize) -> QosProfile {
    QosProfile::subscription_default().durability(Durability::Volatile).history(History::KeepLast { depth })
}

/// QoS of outputs: reliable, volatile.
fn reliable_qos(depth: usize) -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(100)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// QoS of map-like outputs (the occupancy grid), as `map_server`'s: reliable,
/// transient local, keep last 1, so a subscriber that joins late (a Nav2
/// costmap, RViz's Map display) gets the latest at once.
fn map_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(100)))
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}

/// `/tf_static`: reliable, transient local (late joiners get the tree).
fn static_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(100)))
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 100 })
}

/// `topic` resolved in `namespace`, as an absolute name (`ros2-client`
/// would put a double slash in a relative name under the root namespace).
fn name(namespace: &str, topic: &str) -> Result<Name, NodeError> {
    let full =
        if topic.starts_with('/') { topic.to_string() } else { format!("{}/{topic}", namespace.trim_end_matches('/')) };
    Name::parse(&full).map_err(|e| NodeError::Config(format!("topic {full:?} is not a ROS name: {e:?}")))
}

/// `NAMESPACE/edtmap/BASE`: the node's outputs and services.
pub(crate) fn own_name(namespace: &str, base: &str) -> Result<Name, NodeError> {
    name(namespace, &format!("edtmap/{base}"))
}

/// The recording vocabulary of `[ros]`, for the pose logic both share.
fn ros_options(r: &RosSection) -> Result<RosOptions, NodeError> {
    r.validate().map_err(|e| NodeError::Config(e.to_string()))?;
    Ok(RosOptions {
        sensor_topic: r.sensor_topic.clone(),
        camera_info_topic: r.camera_info_topic.clone(),
        pose_topic: r.pose_topic.clone(),
        static_tf_topic: r.static_tf_topic.clone(),
        world_frame: r.world_frame.clone(),
        body_frame: r.body_frame.clone(),
        t_body_sensor: r.t_body_sensor().map_err(|e| NodeError::Config(e.to_string()))?,
        max_pose_gap_s: r.max_pose_gap_s,
        depth_scale_m: r.depth_scale_m,
    })
}

/// The sensor subscription, by the message type `[sensor] kind` takes
/// (one per node: the size of the variants does not matter).
#[allow(clippy::large_enum_variant)]
enum SensorSub {
    Cloud(Subscription<Dds<types::PointCloud2>>),
    Image(Subscription<Dds<types::Image>>, Option<Subscription<Dds<types::CameraInfo>>>),
    Scan(Subscription<Dds<types::LaserScanMsg>>),
}

/// The pose subscription(s).
#[allow(clippy::large_enum_variant)]
enum PoseSub {
    Tf(Subscription<types::TfMessage>, Subscription<types::TfMessage>),
    Odometry(Subscription<types::Odometry>),
    PoseStamped(Subscription<types::PoseStamped>),
    TransformStamped(Subscription<types::TransformStamped>),
}

/// The output publishers.
struct Outputs {
    esdf: Publisher<Dds<types::PointCloud2>>,
    occupied: Publisher<Dds<types::PointCloud2>>,
    slice: Publisher<Dds<types::PointCloud2>>,
    grid: Publisher<types::OccupancyGrid>,
    stats: Publisher<types::DiagnosticArray>,
}

/// The mapper of `config` (all but its `[ros]` section), going on from
/// `map` when given; `max_memory_bytes` replaces `[memory]`'s budget.
pub fn mapper(config: &Config, map: Option<GlobalMap>, max_memory_bytes: Option<u64>) -> Result<Mapper, NodeError> {
    if !config.other_sensors.is_empty() {
        return Err(NodeError::Config(format!(
            "the config lists {} [[sensors]]; the live node maps one sensor: give it a config with one [sensor] section",
            config.other_sensors.len() + 1
        )));
    }
    if SensorMessage::of(config.sensor.kind).is_none() {
        return Err(NodeError::Config("[sensor] kind = \"lidar\" takes range images; a live sensor_msgs/PointCloud2 needs kind = \"points\" (with construction = \"raycast\" or \"projection\")".into()));
    }
    let (sensor, mut params) = config.mapper_params()?;
    if max_memory_bytes.is_some() {
        params.max_memory_bytes = max_memory_bytes;
    }
    Ok(match map {
        Some(map) => Mapper::with_map(sensor, params, map)?,
        None => Mapper::new(sensor, params)?,
    })
}

/// Starts the node `ros` describes, mapping with `mapper` (see
/// [`mapper`]) made from `config`.
pub fn start(config: &Config, ros: &RosSection, mapper: Mapper) -> Result<NodeHandle, NodeError> {
    let opts = ros_options(ros)?;
    if ros.map_clearing_radius_m > 0.0 && mapper.params().global.mode != edtmap::IntegrationMode::Exact {
        return Err(NodeError::Config("map_clearing_radius_m needs [global] mode = \"exact\" (the default)".into()));
    }
    let r = ros;
    let domain: u16 = match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) if !v.trim().is_empty() => v
            .trim()
            .parse()
            .ok()
            .filter(|&d| d <= 232)
            .ok_or_else(|| NodeError::Config(format!("ROS_DOMAIN_ID={v:?} is not a domain id (0 to 232)")))?,
        _ => 0,
    };
    let mut builder = DomainParticipantBuilder::new(domain);
    if r.localhost_only {
        builder = builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
    }
    let participant = builder.build().map_err(|e| NodeError::Dds(format!("joining DDS domain {domain}: {e:?}")))?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| NodeError::Dds(format!("ROS 2 context: {e:?}")))?;
    let node_name = NodeName::new(&r.namespace, "edtmap")
        .map_err(|e| NodeError::Config(format!("namespace {:?}: {e:?}", r.namespace)))?;
    let mut node = context
        .new_node(node_name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| NodeError::Dds(format!("node: {e:?}")))?;

    let ns = r.namespace.as_str();
    let topic = |node: &mut Node, t: &str, package: &str, ty: &str, qos: &QosProfile| {
        node.create_topic(&name(ns, t)?, MessageTypeName::new(package, ty), qos)
            .map_err(|e| NodeError::Dds(format!("topic {t}: {e:?}")))
    };
    let out_topic = |node: &mut Node, base: &str, package: &str, ty: &str, qos: &QosProfile| {
        let n = own_name(ns, base)?;
        node.create_topic(&n, MessageTypeName::new(package, ty), qos)
            .map_err(|e| NodeError::Dds(format!("topic edtmap/{base}: {e:?}")))
    };
    macro_rules! sub {
        ($node:expr, $topic:expr, $qos:expr) => {{
            let topic = $topic;
            $node.create_subscription(&topic, Some($qos)).map_err(|e| NodeError::Dds(format!("subscribing: {e:?}")))?
        }};
    }
    macro_rules! publ {
        ($node:expr, $base:expr, $package:expr, $ty:expr, $qos:expr) => {{
            let qos = $qos;
            let topic = out_topic(&mut $node, $base, $package, $ty, &qos)?;
            $node.create_publisher(&topic, Some(qos)).map_err(|e| NodeError::Dds(format!("publishing: {e:?}")))?
        }};
    }
    let message = SensorMessage::of(config.sensor.kind).unwrap_or(SensorMessage::PointCloud2);
    let sensor_topic = topic(&mut node, &r.sensor_topic, "sensor_msgs", message.name(), &sensor_qos())?;
    let sensor_sub = match message {
        SensorMessage::Image => {
            let t = sensor_topic;
            let info_topic = r.camera_info_topic.clone().unwrap_or_else(|| match r.sensor_topic.rsplit_once('/') {
                Some((parent, _)) => format!("{parent}/camera_info"),
                None => "camera_info".into(),
            });
            let it = topic(&mut node, &info_topic, "sensor_msgs", "CameraInfo", &sensor_qos())?;
            SensorSub::Image(sub!(node, t, sensor_qos()), Some(sub!(node, it, sensor_qos())))
        }
        SensorMessage::LaserScan => SensorSub::Scan(sub!(node, sensor_topic, sensor_qos())),
        SensorMessage::PointCloud2 => SensorSub::Cloud(sub!(node, sensor_topic, sensor_qos())),
    };
    let pose_type = r.pose_type();
    let pose_sub = match pose_type {
        PoseType::Tf => {
            let t = topic(&mut node, &r.pose_topic, "tf2_msgs", "TFMessage", &pose_qos(100))?;
            let s = topic(&mut node, &r.static_tf_topic, "tf2_msgs", "TFMessage", &static_qos())?;
            PoseSub::Tf(sub!(node, t, pose_qos(100)), sub!(node, s, static_qos()))
        }
        PoseType::Odometry => PoseSub::Odometry(sub!(
            node,
            topic(&mut node, &r.pose_topic, "nav_msgs", "Odometry", &pose_qos(100))?,
            pose_qos(100)
        )),
        PoseType::PoseStamped => PoseSub::PoseStamped(sub!(
            node,
            topic(&mut node, &r.pose_topic, "geometry_msgs", "PoseStamped", &pose_qos(100))?,
            pose_qos(100)
        )),
        PoseType::TransformStamped => PoseSub::TransformStamped(sub!(
            node,
            topic(&mut node, &r.pose_topic, "geometry_msgs", "TransformStamped", &pose_qos(100))?,
            pose_qos(100)
        )),
    };
    // Each writer holds its last `depth` samples, delivered or not (the DDS
    // memory budget, see the README): few of the large clouds, more of the
    // small messages.
    let outputs = Outputs {
        esdf: publ!(node, "esdf_pointcloud", "sensor_msgs", "PointCloud2", reliable_qos(4)),
        occupied: publ!(node, "occupied_pointcloud", "sensor_msgs", "PointCloud2", reliable_qos(4)),
        slice: publ!(node, "distance_slice", "sensor_msgs", "PointCloud2", reliable_qos(4)),
        grid: publ!(node, "occupancy_grid", "nav_msgs", "OccupancyGrid", map_qos()),
        stats: publ!(node, "frame_stats", "diagnostic_msgs", "DiagnosticArray", reliable_qos(10)),
    };
    if r.service_mapping != ServiceMapping::Auto {
        tracing::info!(
            "[ros] service_mapping is no longer needed: services answer Fast DDS and Cyclone DDS clients alike"
        );
    }
    let budget = mapper
        .params()
        .max_memory_bytes
        .map_or_else(edtmap_core::MemoryBudget::from_system, edtmap_core::MemoryBudget::with_limit);
    let servers = services::Servers::create(
        &context.domain_participant(),
        ns,
        services::QueryLimits::of_budget(budget.limit_bytes()),
    )?;

    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        slot: Mutex::new(None),
        wake: Condvar::new(),
        mapper: SharedMapper::new(mapper),
        received: AtomicU64::new(0),
        integrated: AtomicU64::new(0),
        dropped: AtomicU64::new(0),
        requests: AtomicU64::new(0),
        skipped: Mutex::new(BTreeMap::new()),
    });
    let needs_camera_info = config.sensor.kind == SensorKind::Depth && r.intrinsics == Intrinsics::CameraInfo;
    let live = LiveFrames::new(opts, pose_type == PoseType::Tf, r.pose_wait_s, r.tf_history_s)
        .with_startup(Instant::now(), r.startup_pose_wait_s);
    let mut threads = Vec::new();
    let s = shared.clone();
    threads.push(
        std::thread::Builder::new()
            .name("edtmap-input".into())
            .spawn(move || input_loop(&s, sensor_sub, pose_sub, live, needs_camera_info))
            .map_err(|e| NodeError::Dds(format!("input thread: {e}")))?,
    );
    let s = shared.clone();
    threads.push(
        std::thread::Builder::new()
            .name("edtmap-services".into())
            .spawn(move || servers.serve(&s))
            .map_err(|e| NodeError::Dds(format!("service thread: {e}")))?,
    );
    let s = shared.clone();
    let rates = Rates::of(ros);
    let camera = needs_camera_info.then(|| config.clone());
    let mapping = std::thread::Builder::new()
        .name("edtmap-mapping".into())
        .spawn(move || mapping_loop(&s, outputs, rates, camera))
        .map_err(|e| NodeError::Dds(format!("mapping thread: {e}")))?;
    tracing::info!(
        "node {}edtmap on ROS 2 domain {domain}: {} on {}, poses from {}",
        if r.namespace == "/" { "/".to_string() } else { format!("{}/", r.namespace) },
        format!("{:?}", config.sensor.kind).to_lowercase(),
        r.sensor_topic,
        r.pose_topic
    );
    Ok(NodeHandle {
        shared,
        threads,
        mapping: Some(mapping),
        save_on_exit: r.save_on_exit.clone(),
        _node: Arc::new(Mutex::new(node)),
    })
}

impl NodeHandle {
    /// The counters so far.
    pub fn stats(&self) -> NodeStats {
        self.shared.stats()
    }

    /// The map after the latest whole frame.
    pub fn snapshot(&self) -> Arc<Snapshot> {
        self.shared.snapshot()
    }

    /// Whether the mapping thread has ended (on an error).
    pub fn is_finished(&self) -> bool {
        self.mapping.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Stops the threads, saves the map when `[ros] save_on_exit` says so,
    /// and returns the counters.
    pub fn stop(mut self) -> Result<NodeStats, NodeError> {
        self.shared.stop.store(true, Relaxed);
        self.shared.wake.notify_all();
        let mapped = match self.mapping.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(NodeError::Dds("the mapping thread panicked".into())),
            None => Ok(()),
        };
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        if let Some(path) = &self.save_on_exit {
            let snap = self.shared.snapshot();
            edtmap::save_map(&snap.map, path)?;
            tracing::info!("saved the map ({} frames) to {}", snap.frames, path.display());
        }
        mapped.map(|()| self.shared.stats())
    }
}

/// Takes every message waiting on one subscription.
fn drain<M: 'static + serde::de::DeserializeOwned>(sub: &Subscription<M>, shared: &Shared, mut f: impl FnMut(M)) {
    loop {
        match sub.take() {
            Ok(Some((m, _))) => f(m),
            Ok(None) => break,
            Err(e) => shared
                .skip(&Skipped { kind: "bad message: undecodable CDR", reason: format!("undecodable sample: {e:?}") }),
        }
    }
}

fn input_loop(
    shared: &Shared,
    mut sensor: SensorSub,
    mut pose: PoseSub,
    mut live: LiveFrames,
    needs_camera_info: bool,
) {
    let Ok(mut poll) = Poll::new() else {
        tracing::error!("input thread: cannot create a poll");
        return;
    };
    let reg = poll.registry();
    let mut ok = true;
    let mut register = |s: &mut dyn ros2_client::dds::rustdds::mio1::event::Source, t: usize| {
        ok &= reg.register(s, Token(t), Interest::READABLE).is_ok()
    };
    match &mut sensor {
        SensorSub::Cloud(s) => register(s, 0),
        SensorSub::Scan(s) => register(s, 0),
        SensorSub::Image(s, info) => {
            register(s, 0);
            if let Some(i) = info {
                register(i, 1);
            }
        }
    }
    match &mut pose {
        PoseSub::Tf(t, st) => {
            register(t, 2);
            register(st, 3);
        }
        PoseSub::Odometry(s) => register(s, 2),
        PoseSub::PoseStamped(s) => register(s, 2),
        PoseSub::TransformStamped(s) => register(s, 2),
    }
    if !ok {
        tracing::warn!("input thread: could not register a subscription with the poll; polling every 5 ms instead");
    }
    let mut events = Events::with_capacity(16);
    while !shared.stop.load(Relaxed) {
        let _ = poll.poll(&mut events, Some(Duration::from_millis(if ok { 20 } else { 5 })));
        let now = Instant::now();
        // Poses first, so a sensor message arriving with its pose is placed at once.
        let pose_msg = |m: Result<Message, String>, is_static: bool, live: &mut LiveFrames| match m {
            Ok(m) => {
                if let Err(s) = live.add_pose(&m, is_static) {
                    shared.skip(&s);
                }
            }
            Err(reason) => shared.skip(&Skipped { kind: "bad pose", reason }),
        };
        match &pose {
            PoseSub::Tf(t, st) => {
                drain(st, shared, |m| pose_msg(types::tf_message(m), true, &mut live));
                drain(t, shared, |m| pose_msg(types::tf_message(m), false, &mut live));
            }
            PoseSub::Odometry(s) => drain(s, shared, |m| pose_msg(types::odometry(m), false, &mut live)),
            PoseSub::PoseStamped(s) => drain(s, shared, |m| pose_msg(types::pose_stamped(m), false, &mut live)),
            PoseSub::TransformStamped(s) => {
                drain(s, shared, |m| pose_msg(types::transform_stamped(m), false, &mut live))
            }
        }
        let sensor_msg = |m: Message, live: &mut LiveFrames| {
            shared.received.fetch_add(1, Relaxed);
            if let Err(s) = live.add_sensor(m, now) {
                shared.skip(&s);
            }
        };
        match &sensor {
            SensorSub::Cloud(s) => drain(s, shared, |m| sensor_msg(Message::PointCloud2(m.0), &mut live)),
            SensorSub::Scan(s) => drain(s, shared, |m| sensor_msg(Message::LaserScan(m.0), &mut live)),
            SensorSub::Image(s, info) => {
                if let Some(i) = info {
                    drain(i, shared, |m| live.set_camera(m.0));
                }
                drain(s, shared, |m| sensor_msg(Message::Image(m.0), &mut live));
            }
        }
        for ready in live.ready(now) {
            match ready {
                Ok(_) if needs_camera_info && live.camera().is_none() => shared.skip(&Skipped {
                    kind: "no camera info yet",
                    reason: "a depth image came before any camera info; [ros] intrinsics = \"camera_info\" maps only with the camera's own intrinsics (\"config\" uses [sensor]'s)".into(),
                }),
                Ok(frame) => {
                    let info = live.camera().cloned();
                    let world = live.world_frame().unwrap_or(DEFAULT_WORLD_FRAME).to_string();
                    let mut slot = shared.slot.lock().unwrap_or_else(PoisonError::into_inner);
                    if slot.replace((frame, info, world)).is_some() {
                        shared.dropped.fetch_add(1, Relaxed);
                    }
                    shared.wake.notify_one();
                }
                Err(s) => shared.skip(&s),
            }
        }
    }
}

/// When each output is due.
struct Rates {
    esdf: Option<Duration>,
    occupied: Option<Duration>,
    slice: Option<Duration>,
    scope: OccupiedScope,
    slice_height_m: f64,
    esdf_z_m: [f64; 2],
    clearing: Option<(f64, Duration)>,
    clearing_save: Option<PathBuf>,
}

impl Rates {
    fn of(r: &RosSection) -> Self {
        let period = |hz: f64| (hz > 0.0).then(|| Duration::from_secs_f64(1.0 / hz));
        let clearing = (r.map_clearing_radius_m > 0.0)
            .then(|| (r.map_clearing_radius_m, Duration::from_secs_f64(r.map_clearing_period_s)));
        let clearing_save = r.map_clearing_save.clone();
        Rates {
            esdf: period(r.esdf_pointcloud_hz),
            occupied: period(r.occupied_pointcloud_hz),
            slice: period(r.slice_hz),
            scope: r.occupied_scope,
            slice_height_m: r.slice_height_m,
            esdf_z_m: r.esdf_pointcloud_z_m,
            clearing,
            clearing_save,
        }
    }
}

/// Whether an output of `period` last sent at `last` is due at `now`.
fn due(period: Option<Duration>, last: &mut Option<Instant>, now: Instant) -> bool {
    match period {
        Some(p) if last.is_none_or(|l| now.duration_since(l) >= p) => {
            *last = Some(now);
            true
        }
        _ => false,
    }
}

/// A depth camera's mapper with the intrinsics of its camera info: the
/// same mapper when they are `[sensor]`'s, a new one on the same map
/// before the first frame, and the same one (with a warning) after it.
fn with_camera(
    mapper: &mut Mapper,
    config: &Config,
    info: &CameraInfo,
    frames: u64,
    warned: &mut bool,
) -> Result<(), String> {
    let edtmap::sensor::Sensor::Depth(c) = mapper.sensor() else { return Ok(()) };
    let k = [info.k[0], info.k[4], info.k[2], info.k[5]];
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
    if (0..4).all(|i| close([c.fx, c.fy, c.cx, c.cy][i], k[i])) && (c.width, c.height) == (info.width, info.height) {
        return Ok(());
    }
    let ours = format!("fx fy cx cy {:?} at {}x{}", [c.fx, c.fy, c.cx, c.cy], c.width, c.height);
    let theirs = format!("{k:?} at {}x{}", info.width, info.height);
    if frames > 0 {
        if !*warned {
            *warned = true;
            tracing::warn!("depth camera: the camera info changed to {theirs} after the first frame, mapped with {ours}: keeping {ours}");
        }
        return Ok(());
    }
    let mut config = config.clone();
    let s = &mut config.sensor.camera;
    (s.fx, s.fy, s.cx, s.cy, s.width, s.height) =
        (Some(k[0]), Some(k[1]), Some(k[2]), Some(k[3]), Some(info.width), Some(info.height));
    let max_memory = mapper.params().max_memory_bytes;
    let map = mapper.map().clone();
    let with_info = self::mapper(&config, Some(map), max_memory)
        .map_err(|e| format!("the camera info's intrinsics {theirs} are refused: {e}"))?;
    tracing::info!("depth camera: mapping with the camera info's {theirs} (the config said {ours})");
    *mapper = with_info;
    Ok(())
}

fn mapping_loop(shared: &Shared, out: Outputs, rates: Rates, camera: Option<Config>) -> Result<(), NodeError> {
    let (mut last_esdf, mut last_occ, mut last_slice, mut last_clear) = (None, None, None, None);
    let mut cleared_blocks = 0usize;
    let mut warned = false;
    loop {
        let frame = {
            let mut slot = shared.slot.lock().unwrap_or_else(PoisonError::into_inner);
            loop {
                if shared.stop.load(Relaxed) {
                    return Ok(());
                }
                if let Some(f) = slot.take() {
                    break f;
                }
                slot = shared
                    .wake
                    .wait_timeout(slot, Duration::from_millis(100))
                    .unwrap_or_else(PoisonError::into_inner)
                    .0;
            }
        };
        let (frame, info, world) = frame;
        let mut mapper = shared.mapper.lock()?;
        if let (Some(config), Some(info)) = (&camera, &info) {
            if let Err(reason) = with_camera(&mut mapper, config, info, shared.integrated.load(Relaxed), &mut warned) {
                shared.skip(&Skipped { kind: "bad camera info", reason });
                continue;
            }
        }
        let stamp_ns = (frame.stamp_s * 1e9).round() as i64;
        let stats = match mapper.integrate_frame(&frame) {
            Ok(stats) => stats,
            Err(e) if e.is_backend_failure() => return Err(e.into()),
            Err(e) => {
                shared.skip(&Skipped {
                    kind: "mapper refused",
                    reason: format!("frame at stamp {:.6} s: {e}", frame.stamp_s),
                });
                continue;
            }
        };
        let frames = shared.integrated.fetch_add(1, Relaxed) + 1;
        if let Some((radius, period)) = rates.clearing {
            if due(Some(period), &mut last_clear, Instant::now()) {
                let at = frame.t_world_sensor.translation.vector;
                let centre = [at.x, at.y, at.z];
                if let Some(path) = &rates.clearing_save {
                    if mapper.would_clear(centre, radius) {
                        // Keep what is about to be forgotten; a failure to save
                        // is reported and the clearing waits for the next period.
                        if let Err(e) = edtmap::save_map(mapper.map(), path) {
                            shared.skip(&Skipped {
                                kind: "map not saved before clearing",
                                reason: format!("{}: {e}", path.display()),
                            });
                            continue;
                        }
                    }
                }
                let c = mapper.clear_far(centre, radius)?;
                cleared_blocks += c.occupancy_blocks;
                if c.occupancy_blocks > 0 {
                    tracing::debug!(
                        "cleared {} occupancy and {} EDT blocks farther than {radius} m: {} → {} bytes",
                        c.occupancy_blocks,
                        c.edt_blocks,
                        c.bytes_before,
                        c.bytes_after
                    );
                }
            }
        }
        let snapshot = shared.mapper.publish(&mapper, stamp_ns, frames);
        let volume = snapshot.volume;
        let header = types::Header { stamp_ns, frame_id: world.clone() };
        let now = Instant::now();
        let publish_failed = |what: &str, e: String| tracing::debug!("publishing {what}: {e}");
        if let Some(volume) = &volume {
            if due(rates.esdf, &mut last_esdf, now) {
                if let Err(e) =
                    out.esdf.publish(Dds(outputs::esdf_cloud(&snapshot.map, volume, rates.esdf_z_m, header.clone())))
                {
                    publish_failed("esdf_pointcloud", format!("{e:?}"));
                }
            }
            if due(rates.occupied, &mut last_occ, now) {
                let scope = (rates.scope == OccupiedScope::Window).then_some(volume);
                if let Err(e) = out.occupied.publish(Dds(outputs::occupied_cloud(&snapshot.map, scope, header.clone())))
                {
                    publish_failed("occupied_pointcloud", format!("{e:?}"));
                }
            }
            if due(rates.slice, &mut last_slice, now) {
                let (cloud, grid) = outputs::slice(&snapshot.map, volume, rates.slice_height_m, header.clone());
                if let Err(e) = out.slice.publish(Dds(cloud)) {
                    publish_failed("distance_slice", format!("{e:?}"));
                }
                if let Err(e) = out.grid.publish(grid) {
                    publish_failed("occupancy_grid", format!("{e:?}"));
                }
            }
        }
        let st = shared.stats();
        let skipped: u64 = st.skipped.values().sum();
        let mut values = vec![
            ("frames", frames.to_string()),
            ("received", st.received.to_string()),
            ("dropped", st.dropped.to_string()),
            ("skipped", skipped.to_string()),
            ("ogm_ms", format!("{:.3}", stats.ogm_ms)),
            ("integrate_ms", format!("{:.3}", stats.integrate_ms)),
            ("total_ms", format!("{:.3}", stats.total_ms)),
            ("voxels_updated", stats.voxels_updated.to_string()),
            ("edt_voxels_changed", stats.edt_voxels_changed.to_string()),
            ("map_blocks", (mapper.map().occupancy().len() + mapper.map().edt().len()).to_string()),
            ("map_bytes", mapper.map().bytes().to_string()),
            ("kept_bytes", mapper.backend().kept_bytes().to_string()),
            ("cleared_blocks", cleared_blocks.to_string()),
        ];
        values.extend(st.skipped.iter().map(|(k, v)| ("skipped_kind", format!("{k}: {v}"))));
        let level = u8::from(st.dropped + skipped > 0);
        let message = format!("frame {frames} in {:.1} ms", stats.total_ms);
        if let Err(e) =
            out.stats.publish(outputs::frame_stats(Time::from_ns(header.stamp_ns), &world, level, message, values))
        {
            publish_failed("frame_stats", format!("{e:?}"));
        }
    }
}
