//! `edtmap node`: the mapper live on ROS 2, over DDS in pure Rust
//! (`ros2-client` and RustDDS; no ROS installation).
//!
//! Three threads share the work:
//! - **input** takes the sensor, pose and camera-info messages as they
//!   arrive (one subscription per sensor of the config), waits for each
//!   sensor message's pose ([`live`]), and leaves the frame in its sensor's
//!   one-place slot: when a sensor's frames come faster than they are
//!   mapped, the newest wins and the one it replaces is counted as dropped;
//! - **mapping** integrates the slots' frames, the oldest stamp first (a
//!   tie in the config's order of the sensors), then hands the queries a new
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
use edtmap::{FrameThreads, GlobalMap, MapError, Mapper, SharedMapper};
use edtmap_ros::config::{sensor_topics, LoneSensor};
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
    /// Each sensor's counts, in the config's order.
    pub sensors: Vec<SensorStats>,
}

/// Counters of one of a running node's sensors.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SensorStats {
    /// The sensor's name (its `[[sensors]]` entry's, or its kind's).
    pub name: String,
    /// Its topic.
    pub topic: String,
    /// Messages received on its topic.
    pub received: u64,
    /// Its frames integrated.
    pub integrated: u64,
    /// Its frames replaced in its slot by a newer one before they were mapped.
    pub dropped: u64,
}

/// The frame outputs are labelled with before any pose said otherwise.
const DEFAULT_WORLD_FRAME: &str = "map";

/// A frame waiting to be mapped: the frame, its camera's latest info (a
/// depth camera) and the fixed frame its pose is in.
type Slot = (Frame, Option<CameraInfo>, String);

/// One sensor's counters.
struct SensorCounters {
    name: String,
    topic: String,
    received: AtomicU64,
    integrated: AtomicU64,
    dropped: AtomicU64,
}

/// What the threads share.
struct Shared {
    stop: AtomicBool,
    /// Each sensor's newest frame not yet mapped.
    slots: Mutex<Vec<Option<Slot>>>,
    wake: Condvar,
    /// The mapper (locked by the mapping thread) and the snapshot the
    /// services read.
    mapper: SharedMapper<CpuBackend>,
    requests: AtomicU64,
    skipped: Mutex<BTreeMap<String, u64>>,
    /// Per sensor, in the config's order; the node's totals are their sums.
    sensors: Vec<SensorCounters>,
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

    /// Frames integrated, of every sensor.
    fn integrated(&self) -> u64 {
        self.sensors.iter().map(|c| c.integrated.load(Relaxed)).sum()
    }

    fn stats(&self) -> NodeStats {
        let sensors: Vec<SensorStats> = self
            .sensors
            .iter()
            .map(|c| SensorStats {
                name: c.name.clone(),
                topic: c.topic.clone(),
                received: c.received.load(Relaxed),
                integrated: c.integrated.load(Relaxed),
                dropped: c.dropped.load(Relaxed),
            })
            .collect();
        NodeStats {
            received: sensors.iter().map(|s| s.received).sum(),
            integrated: sensors.iter().map(|s| s.integrated).sum(),
            dropped: sensors.iter().map(|s| s.dropped).sum(),
            skipped: self.skipped.lock().unwrap_or_else(PoisonError::into_inner).clone(),
            requests: self.requests.load(Relaxed),
            sensors,
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

/// The recording vocabulary of `[ros]` and the config's sensors, for the
/// pose logic both share: each sensor's topic, camera info topic and mount
/// from its `[[sensors]]` entry, or for a lone sensor from `[ros]`
/// (`sensor_topic`, by default `/points`).
fn ros_options(r: &RosSection, config: &Config) -> Result<RosOptions, NodeError> {
    r.validate().map_err(|e| NodeError::Config(e.to_string()))?;
    let default_topic = (config.other_sensors.is_empty() && config.sensor.topic.is_none() && r.sensor_topic.is_none())
        .then_some("/points");
    let lone = LoneSensor {
        section: "[ros]",
        topic: r.sensor_topic.as_deref().or(default_topic),
        camera_info_topic: r.camera_info_topic.as_deref(),
        sensor_in_body: r.sensor_in_body,
        needed: "for the live node",
    };
    let sensors =
        sensor_topics(config, &lone).map_err(|e| NodeError::Config(e.trim_start_matches("[ros] ").to_string()))?;
    Ok(RosOptions {
        sensors,
        pose_topic: r.pose_topic.clone(),
        static_tf_topic: r.static_tf_topic.clone(),
        world_frame: r.world_frame.clone(),
        body_frame: r.body_frame.clone(),
        max_pose_gap_s: r.max_pose_gap_s,
        depth_scale_m: r.depth_scale_m,
    })
}

/// A sensor's subscription, by the message type its kind takes (one per
/// sensor: the size of the variants does not matter).
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
    for s in config.sensors() {
        if SensorMessage::of(s.kind).is_none() {
            let which =
                if config.other_sensors.is_empty() { "[sensor]".into() } else { format!("[[sensors]] {:?}", s.name()) };
            return Err(NodeError::Config(format!("{which} kind = \"lidar\" takes range images; a live sensor_msgs/PointCloud2 needs kind = \"points\" (with construction = \"raycast\" or \"projection\")")));
        }
    }
    let (sensor, mut params) = config.mapper_params()?;
    if max_memory_bytes.is_some() {
        params.max_memory_bytes = max_memory_bytes;
    }
    let mut mapper = match map {
        Some(map) => Mapper::with_map(sensor, params, map)?,
        None => Mapper::new(sensor, params)?,
    };
    config.add_sensors_to(&mut mapper)?;
    Ok(mapper)
}

/// Starts the node `ros` describes, mapping with `mapper` (see
/// [`mapper`]) made from `config`.
pub fn start(config: &Config, ros: &RosSection, mapper: Mapper) -> Result<NodeHandle, NodeError> {
    let opts = ros_options(ros, config)?;
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
    let mut sensor_subs = Vec::new();
    for (section, st) in config.sensors().zip(&opts.sensors) {
        let message = SensorMessage::of(section.kind).unwrap_or(SensorMessage::PointCloud2);
        let sensor_topic = topic(&mut node, &st.topic, "sensor_msgs", message.name(), &sensor_qos())?;
        sensor_subs.push(match message {
            SensorMessage::Image => {
                let it = topic(&mut node, &st.camera_info(), "sensor_msgs", "CameraInfo", &sensor_qos())?;
                SensorSub::Image(sub!(node, sensor_topic, sensor_qos()), Some(sub!(node, it, sensor_qos())))
            }
            SensorMessage::LaserScan => SensorSub::Scan(sub!(node, sensor_topic, sensor_qos())),
            SensorMessage::PointCloud2 => SensorSub::Cloud(sub!(node, sensor_topic, sensor_qos())),
        });
    }
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
    // memory budget, see docs/ros2.md): few of the large clouds, more of the
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

    let names: Vec<String> = mapper.sensors().iter().map(|s| s.name.clone()).collect();
    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        slots: Mutex::new(vec![None; names.len()]),
        wake: Condvar::new(),
        mapper: SharedMapper::new(mapper),
        requests: AtomicU64::new(0),
        skipped: Mutex::new(BTreeMap::new()),
        sensors: names
            .into_iter()
            .zip(&opts.sensors)
            .map(|(name, st)| SensorCounters {
                name,
                topic: st.topic.clone(),
                received: AtomicU64::new(0),
                integrated: AtomicU64::new(0),
                dropped: AtomicU64::new(0),
            })
            .collect(),
    });
    let needs_camera_info: Vec<bool> =
        config.sensors().map(|s| s.kind == SensorKind::Depth && r.intrinsics == Intrinsics::CameraInfo).collect();
    let any_camera_info = needs_camera_info.iter().any(|&n| n);
    let topics = opts.sensors.iter().map(|s| s.topic.clone()).collect::<Vec<_>>().join(", ");
    let live = LiveFrames::new(opts, pose_type == PoseType::Tf, r.pose_wait_s, r.tf_history_s)
        .with_startup(Instant::now(), r.startup_pose_wait_s);
    let mut threads = Vec::new();
    let s = shared.clone();
    threads.push(
        std::thread::Builder::new()
            .name("edtmap-input".into())
            .spawn(move || input_loop(&s, sensor_subs, pose_sub, live, &needs_camera_info))
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
    let camera = any_camera_info.then(|| config.clone());
    let mapping = std::thread::Builder::new()
        .name("edtmap-mapping".into())
        .spawn(move || mapping_loop(&s, outputs, rates, camera))
        .map_err(|e| NodeError::Dds(format!("mapping thread: {e}")))?;
    tracing::info!(
        "node {}edtmap on ROS 2 domain {domain}: {} on {}, poses from {}",
        if r.namespace == "/" { "/".to_string() } else { format!("{}/", r.namespace) },
        config.sensors().map(|s| format!("{:?}", s.kind).to_lowercase()).collect::<Vec<_>>().join(", "),
        topics,
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

/// Tokens of the poll: poses first, then two per sensor (its messages,
/// its camera info).
const POSE_TOKEN: usize = 0;
const STATIC_TF_TOKEN: usize = 1;
const SENSOR_TOKENS: usize = 2;

fn input_loop(
    shared: &Shared,
    mut sensors: Vec<SensorSub>,
    mut pose: PoseSub,
    mut live: LiveFrames,
    needs_camera_info: &[bool],
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
    for (k, sensor) in sensors.iter_mut().enumerate() {
        let token = SENSOR_TOKENS + 2 * k;
        match sensor {
            SensorSub::Cloud(s) => register(s, token),
            SensorSub::Scan(s) => register(s, token),
            SensorSub::Image(s, info) => {
                register(s, token);
                if let Some(i) = info {
                    register(i, token + 1);
                }
            }
        }
    }
    match &mut pose {
        PoseSub::Tf(t, st) => {
            register(t, POSE_TOKEN);
            register(st, STATIC_TF_TOKEN);
        }
        PoseSub::Odometry(s) => register(s, POSE_TOKEN),
        PoseSub::PoseStamped(s) => register(s, POSE_TOKEN),
        PoseSub::TransformStamped(s) => register(s, POSE_TOKEN),
    }
    if !ok {
        tracing::warn!("input thread: could not register a subscription with the poll; polling every 5 ms instead");
    }
    let mut events = Events::with_capacity(16 + 2 * sensors.len());
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
        let sensor_msg = |k: usize, m: Message, live: &mut LiveFrames| {
            shared.sensors[k].received.fetch_add(1, Relaxed);
            if let Err(s) = live.add_sensor(k, m, now) {
                shared.skip(&s);
            }
        };
        for (k, sensor) in sensors.iter().enumerate() {
            match sensor {
                SensorSub::Cloud(s) => drain(s, shared, |m| sensor_msg(k, Message::PointCloud2(m.0), &mut live)),
                SensorSub::Scan(s) => drain(s, shared, |m| sensor_msg(k, Message::LaserScan(m.0), &mut live)),
                SensorSub::Image(s, info) => {
                    if let Some(i) = info {
                        drain(i, shared, |m| live.set_camera(k, m.0));
                    }
                    drain(s, shared, |m| sensor_msg(k, Message::Image(m.0), &mut live));
                }
            }
        }
        for (k, ready) in live.ready(now) {
            match ready {
                Ok(_) if needs_camera_info[k] && live.camera(k).is_none() => shared.skip(&Skipped {
                    kind: "no camera info yet",
                    reason: format!("a depth image of {:?} came before any camera info; [ros] intrinsics = \"camera_info\" maps only with the camera's own intrinsics (\"config\" uses the config's)", shared.sensors[k].name),
                }),
                Ok(frame) => {
                    let info = live.camera(k).cloned();
                    let world = live.world_frame().unwrap_or(DEFAULT_WORLD_FRAME).to_string();
                    let mut slots = shared.slots.lock().unwrap_or_else(PoisonError::into_inner);
                    if slots[k].replace((frame, info, world)).is_some() {
                        shared.sensors[k].dropped.fetch_add(1, Relaxed);
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

/// Depth camera `k` of the mapper with the intrinsics of its camera info:
/// kept when they are the config's, replaced (the map kept) before the
/// camera's first frame, and kept with a warning after it.
fn with_camera(
    mapper: &mut Mapper,
    config: &Config,
    k: usize,
    info: &CameraInfo,
    frames: u64,
    warned: &mut bool,
) -> Result<(), String> {
    let Some(edtmap::sensor::Sensor::Depth(c)) = mapper.sensors().get(k).map(|s| &s.sensor) else { return Ok(()) };
    let k_info = [info.k[0], info.k[4], info.k[2], info.k[5]];
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
    if (0..4).all(|i| close([c.fx, c.fy, c.cx, c.cy][i], k_info[i])) && (c.width, c.height) == (info.width, info.height)
    {
        return Ok(());
    }
    let name = &mapper.sensors()[k].name;
    let ours = format!("fx fy cx cy {:?} at {}x{}", [c.fx, c.fy, c.cx, c.cy], c.width, c.height);
    let theirs = format!("{k_info:?} at {}x{}", info.width, info.height);
    if frames > 0 {
        if !*warned {
            *warned = true;
            tracing::warn!("depth camera {name:?}: the camera info changed to {theirs} after the first frame, mapped with {ours}: keeping {ours}");
        }
        return Ok(());
    }
    let Some(mut section) = config.sensors().nth(k).cloned() else { return Ok(()) };
    let s = &mut section.camera;
    (s.fx, s.fy, s.cx, s.cy, s.width, s.height) =
        (Some(k_info[0]), Some(k_info[1]), Some(k_info[2]), Some(k_info[3]), Some(info.width), Some(info.height));
    let refused = |e: String| format!("the camera info's intrinsics {theirs} are refused: {e}");
    let (sensor, ogm) = section.checked().map_err(|e| refused(e.to_string()))?;
    mapper
        .replace_sensor(k, edtmap::MapperSensor { name: name.clone(), sensor, ogm })
        .map_err(|e| refused(e.to_string()))?;
    tracing::info!(
        "depth camera {:?}: mapping with the camera info's {theirs} (the config said {ours})",
        mapper.sensors()[k].name
    );
    Ok(())
}

fn mapping_loop(shared: &Shared, out: Outputs, rates: Rates, camera: Option<Config>) -> Result<(), NodeError> {
    let (mut last_esdf, mut last_occ, mut last_slice, mut last_clear) = (None, None, None, None);
    let mut cleared_blocks = 0usize;
    let mut warned = vec![false; shared.sensors.len()];
    let mut threads = FrameThreads::new();
    loop {
        let (k, frame) = {
            let mut slots = shared.slots.lock().unwrap_or_else(PoisonError::into_inner);
            loop {
                if shared.stop.load(Relaxed) {
                    return Ok(());
                }
                // The oldest stamp first; on a tie, the first sensor.
                let oldest = slots
                    .iter()
                    .enumerate()
                    .filter_map(|(k, s)| s.as_ref().map(|(f, _, _)| (k, f.stamp_s)))
                    .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                if let Some(f) = oldest.and_then(|(k, _)| slots[k].take().map(|f| (k, f))) {
                    break f;
                }
                slots = shared
                    .wake
                    .wait_timeout(slots, Duration::from_millis(100))
                    .unwrap_or_else(PoisonError::into_inner)
                    .0;
            }
        };
        let (frame, info, world) = frame;
        let counters = &shared.sensors[k];
        let mut mapper = shared.mapper.lock()?;
        if let (Some(config), Some(info)) = (&camera, &info) {
            let mapped = counters.integrated.load(Relaxed);
            if let Err(reason) = with_camera(&mut mapper, config, k, info, mapped, &mut warned[k]) {
                shared.skip(&Skipped { kind: "bad camera info", reason });
                continue;
            }
        }
        let stamp_ns = (frame.stamp_s * 1e9).round() as i64;
        let on: &mut Mapper = &mut mapper;
        let stats = match threads.run(|| on.integrate_sensor_frame(k, &frame)) {
            Ok(stats) => stats,
            Err(e) if e.is_backend_failure() => return Err(e.into()),
            Err(e) => {
                shared.skip(&Skipped {
                    kind: "mapper refused",
                    reason: format!("frame of {:?} at stamp {:.6} s: {e}", counters.name, frame.stamp_s),
                });
                continue;
            }
        };
        counters.integrated.fetch_add(1, Relaxed);
        // Only this thread integrates: the sum is this frame's number.
        let frames = shared.integrated();
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
            ("sensor", counters.name.clone()),
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
        if st.sensors.len() > 1 {
            values.extend(st.sensors.iter().map(|s| {
                (
                    "sensor_counts",
                    format!("{}: {} received, {} integrated, {} dropped", s.name, s.received, s.integrated, s.dropped),
                )
            }));
        }
        let level = u8::from(st.dropped + skipped > 0);
        let message = format!("frame {frames} in {:.1} ms", stats.total_ms);
        if let Err(e) =
            out.stats.publish(outputs::frame_stats(Time::from_ns(header.stamp_ns), &world, level, message, values))
        {
            publish_failed("frame_stats", format!("{e:?}"));
        }
    }
}
