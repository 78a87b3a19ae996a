//! Sensor messages become frames as their poses arrive: each waits (in
//! arrival order) until the pose source has passed its stamp, then takes
//! its pose exactly as a recording's replay would; one that waits longer
//! than `pose_wait_s` is given up with the lookup's reason.
//!
//! While discovery settles after the node starts, the transforms often
//! come later than the first sensor messages (`/tf_static` is matched
//! only once its publisher is discovered). For `startup_pose_wait_s` from
//! the start, a message past its own wait keeps waiting until that
//! window ends, the newest [`MAX_STARTUP_WAITING`] of them; then the
//! per-message wait alone applies.

use edtmap_core::sensor::{Frame, Measurement};
use edtmap_ros::msg::{CameraInfo, Message};
use edtmap_ros::poses::{measurement, Poses};
use edtmap_ros::RosOptions;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Most sensor messages waiting for a pose; more drop the oldest.
pub(crate) const MAX_PENDING: usize = 64;
/// Most messages kept past their own wait during the startup window; more
/// give up the oldest.
pub(crate) const MAX_STARTUP_WAITING: usize = 4;

/// What happened to a sensor message that did not become a frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Skipped {
    /// A short kind for counting and logging once (`missing transform`,
    /// `bad message: ...` per malformation, `pose queue full`).
    pub(crate) kind: &'static str,
    /// The whole reason.
    pub(crate) reason: String,
}

/// The kind a malformed sensor message is counted and logged under, one
/// per malformation, from the decoder's reason.
pub(crate) fn malformation(reason: &str) -> &'static str {
    const KINDS: [(&str, &[&str], &str); 12] = [
        ("PointCloud2", &["has no field"], "bad message: PointCloud2 without x, y or z"),
        ("PointCloud2", &["unknown datatype"], "bad message: PointCloud2 field of unknown datatype"),
        ("PointCloud2", &["exceeds point_step"], "bad message: PointCloud2 point_step < its fields"),
        ("PointCloud2", &["row_step"], "bad message: PointCloud2 row_step < width × point_step"),
        ("PointCloud2", &["bytes of data"], "bad message: PointCloud2 data shorter than its points"),
        ("Image", &["encoding"], "bad message: Image encoding not a depth"),
        ("Image", &["is empty"], "bad message: Image empty"),
        ("Image", &["step"], "bad message: Image step < width × pixel"),
        ("Image", &["needs"], "bad message: Image data shorter than its rows"),
        ("LaserScan", &["no ranges"], "bad message: LaserScan without ranges"),
        ("LaserScan", &["angle", "turn"], "bad message: LaserScan angles"),
        ("LaserScan", &[""], "bad message: LaserScan other"),
    ];
    for (prefix, words, kind) in KINDS {
        if reason.starts_with(prefix) && words.iter().any(|w| reason.contains(w)) {
            return kind;
        }
    }
    "bad message: other"
}

struct Pending {
    /// The sensor's position in the options' sensors.
    sensor: usize,
    measurement: Measurement,
    stamp_s: f64,
    frame_id: String,
    arrived: Instant,
}

/// Poses and the sensor messages waiting for them.
pub(crate) struct LiveFrames {
    opts: RosOptions,
    poses: Poses,
    pending: VecDeque<Pending>,
    wait: Duration,
    /// The end of the startup window.
    startup_until: Instant,
    history_s: f64,
    newest_pose_s: f64,
    /// Each sensor's latest camera info.
    cameras: Vec<Option<CameraInfo>>,
    /// The frame of the latest pose topic message.
    pose_frame: Option<String>,
    /// The fixed frame of the latest frame placed.
    world_frame: Option<String>,
}

impl LiveFrames {
    /// Frames placed by `opts`; `is_tf` when poses come from `/tf`. No
    /// startup window until [`Self::with_startup`].
    pub(crate) fn new(opts: RosOptions, is_tf: bool, wait_s: f64, history_s: f64) -> Self {
        let poses = Poses::new(is_tf, &opts);
        let sensors = opts.sensors.len();
        let wait = Duration::try_from_secs_f64(wait_s).unwrap_or(Duration::ZERO);
        LiveFrames {
            opts,
            poses,
            pending: VecDeque::new(),
            wait,
            startup_until: Instant::now(),
            history_s,
            newest_pose_s: f64::NEG_INFINITY,
            cameras: vec![None; sensors],
            pose_frame: None,
            world_frame: None,
        }
    }

    /// A startup window of `wait_s` from `started`, during which messages
    /// wait for their transforms up to its end.
    pub(crate) fn with_startup(mut self, started: Instant, wait_s: f64) -> Self {
        self.startup_until = started + Duration::try_from_secs_f64(wait_s).unwrap_or(Duration::ZERO);
        self
    }

    /// Adds a pose message (`is_static` for `/tf_static`).
    pub(crate) fn add_pose(&mut self, msg: &Message, is_static: bool) -> Result<(), Skipped> {
        self.poses.add(msg, is_static, &self.opts).map_err(|reason| Skipped { kind: "bad pose", reason })?;
        let newest = match msg {
            Message::Tf(ts) if !is_static => ts.iter().map(|t| t.header.stamp_s()).fold(f64::NEG_INFINITY, f64::max),
            Message::Odometry(t) | Message::PoseStamped(t) | Message::TransformStamped(t) => {
                self.pose_frame = Some(t.header.frame_id.trim_start_matches('/').to_string());
                t.header.stamp_s()
            }
            _ => f64::NEG_INFINITY,
        };
        if newest > self.newest_pose_s {
            self.newest_pose_s = newest;
            self.poses.forget_before(newest - self.history_s);
        }
        Ok(())
    }

    /// Keeps sensor `k`'s camera intrinsics (the latest).
    pub(crate) fn set_camera(&mut self, k: usize, info: CameraInfo) {
        if let Some(slot) = self.cameras.get_mut(k) {
            *slot = Some(info);
        }
    }

    /// Sensor `k`'s latest camera info.
    pub(crate) fn camera(&self, k: usize) -> Option<&CameraInfo> {
        self.cameras.get(k).and_then(Option::as_ref)
    }

    /// The fixed frame the latest frame's pose is in: `world_frame` when
    /// configured, else the pose topic's frame, or the root of the
    /// transform tree above the sensor (`None` before any frame).
    pub(crate) fn world_frame(&self) -> Option<&str> {
        self.world_frame.as_deref()
    }

    fn fixed_frame(&self, sensor_frame: &str) -> Option<String> {
        if let Some(w) = &self.opts.world_frame {
            return Some(w.trim_start_matches('/').to_string());
        }
        match &self.poses {
            Poses::Topic(_) => self.pose_frame.clone(),
            Poses::Tf(tf, _) => tf.root_of(self.opts.body_frame.as_deref().unwrap_or(sensor_frame)),
        }
    }

    /// Queues a sensor message until its pose is known; a message that
    /// does not decode is skipped at once. The stamp is taken as it is
    /// (0 included: simulated time starts there), in the poses' clock.
    pub(crate) fn add_sensor(&mut self, sensor: usize, msg: Message, now: Instant) -> Result<(), Skipped> {
        let (measurement, stamp_ns, frame_id) = measurement(msg, self.opts.depth_scale_m)
            .map_err(|reason| Skipped { kind: malformation(&reason), reason })?;
        let stamp_s = stamp_ns as f64 * 1e-9;
        self.pending.push_back(Pending { sensor, measurement, stamp_s, frame_id, arrived: now });
        if self.pending.len() > MAX_PENDING {
            if let Some(old) = self.pending.pop_front() {
                return Err(Skipped {
                    kind: "pose queue full",
                    reason: format!(
                        "{MAX_PENDING} messages were waiting for poses; the oldest (stamp {:.6} s) was dropped",
                        old.stamp_s
                    ),
                });
            }
        }
        Ok(())
    }

    /// Messages waiting for a pose.
    #[cfg(test)]
    pub(crate) fn pending(&self) -> usize {
        self.pending.len()
    }

    /// The frames whose pose has come, in arrival order, and the messages
    /// given up on: those that waited past `pose_wait_s`, and those whose
    /// pose cannot be had although the poses have passed their stamp (a
    /// gap, an unknown frame).
    /// Each comes with its sensor's position.
    pub(crate) fn ready(&mut self, now: Instant) -> Vec<(usize, Result<Frame, Skipped>)> {
        let mut out = Vec::new();
        let starting = now < self.startup_until;
        while let Some(p) = self.pending.front() {
            let passed = self.poses.latest(&p.frame_id, &self.opts).is_some_and(|latest| latest >= p.stamp_s);
            let expired = now.saturating_duration_since(p.arrived) >= self.wait;
            // Past their own wait, the oldest messages form a prefix of the queue.
            let held = starting
                && expired
                && self
                    .pending
                    .iter()
                    .take(MAX_STARTUP_WAITING + 1)
                    .take_while(|q| now.saturating_duration_since(q.arrived) >= self.wait)
                    .count()
                    <= MAX_STARTUP_WAITING;
            if !passed && (!expired || held) {
                break;
            }
            let Some(p) = self.pending.pop_front() else { break };
            let waited = now.saturating_duration_since(p.arrived).as_secs_f64();
            let mount = self.opts.sensors.get(p.sensor).map_or_else(nalgebra::Isometry3::identity, |s| s.t_body_sensor);
            let placed = match self.poses.sensor_pose(p.stamp_s, &p.frame_id, &mount, &self.opts) {
                Ok(t_world_sensor) => {
                    self.world_frame = self.fixed_frame(&p.frame_id).or(self.world_frame.take());
                    Ok(Frame { stamp_s: p.stamp_s, t_world_sensor, measurement: p.measurement })
                }
                Err(e) => Err(Skipped {
                    kind: "missing transform",
                    reason: format!(
                        "no pose for the message at stamp {:.6} s in frame {:?} after waiting {waited:.3} s: {e}",
                        p.stamp_s, p.frame_id
                    ),
                }),
            };
            out.push((p.sensor, placed));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap_ros::msg::{Header, PointCloud2, StampedTransform};
    use edtmap_ros::SensorTopic;
    use nalgebra::{Isometry3, Vector3};

    fn opts() -> RosOptions {
        RosOptions {
            sensors: vec![edtmap_ros::SensorTopic::new("/points")],
            pose_topic: "/tf".into(),
            static_tf_topic: "/tf_static".into(),
            world_frame: Some("map".into()),
            body_frame: None,
            max_pose_gap_s: 1.0,
            depth_scale_m: 0.001,
        }
    }

    fn tf(parent: &str, child: &str, t: f64, x: f64) -> Message {
        let header = Header { stamp_ns: (t * 1e9) as i64, frame_id: parent.into() };
        Message::Tf(vec![StampedTransform {
            header,
            child_frame: child.into(),
            transform: Isometry3::translation(x, 0.0, 0.0),
        }])
    }

    fn cloud(t: f64) -> Message {
        Message::PointCloud2(PointCloud2::from_points(
            Header { stamp_ns: (t * 1e9) as i64, frame_id: "lidar".into() },
            &[[1.0, 0.0, 0.0]],
        ))
    }

    #[test]
    fn a_message_waits_for_poses_past_its_stamp_then_interpolates() {
        let mut live = LiveFrames::new(opts(), true, 0.5, 10.0);
        let t0 = Instant::now();
        live.add_pose(&tf("base_link", "lidar", 0.0, 0.25), true).expect("static");
        live.add_pose(&tf("map", "base_link", 1.0, 1.0), false).expect("pose");
        live.add_sensor(0, cloud(1.5), t0).expect("decodes");
        // The tree ends at 1.0 s: the message at 1.5 s waits.
        assert!(live.ready(t0).is_empty());
        live.add_pose(&tf("map", "base_link", 2.0, 3.0), false).expect("pose");
        let frames = live.ready(t0);
        let frame = frames[0].1.as_ref().expect("pose found");
        // Halfway from x 1 to x 3, plus the static 0.25 m of the sensor.
        assert!((frame.t_world_sensor.translation.vector - Vector3::new(2.25, 0.0, 0.0)).norm() < 1e-12);
        assert_eq!(live.pending(), 0);
    }

    #[test]
    fn each_sensor_takes_its_own_mount_and_a_bad_message_skips_alone() {
        // Two sensors on the body, extrinsics from the config: 0.25 m and
        // 0.5 m ahead.
        let mount =
            |x: f64| SensorTopic { t_body_sensor: Isometry3::translation(x, 0.0, 0.0), ..SensorTopic::new("/a") };
        let opts = RosOptions {
            sensors: vec![mount(0.25), SensorTopic { topic: "/b".into(), ..mount(0.5) }],
            body_frame: Some("base_link".into()),
            ..opts()
        };
        let mut live = LiveFrames::new(opts, true, 0.5, 10.0);
        let t0 = Instant::now();
        live.add_pose(&tf("map", "base_link", 1.0, 1.0), false).expect("pose");
        live.add_pose(&tf("map", "base_link", 2.0, 3.0), false).expect("pose");
        live.add_sensor(1, cloud(1.5), t0).expect("decodes");
        let mut bad =
            PointCloud2::from_points(Header { stamp_ns: 1_500_000_000, frame_id: "b".into() }, &[[1.0, 0.0, 0.0]]);
        bad.data.truncate(3);
        let skipped = live.add_sensor(1, Message::PointCloud2(bad), t0).expect_err("cut short");
        assert!(skipped.kind.starts_with("bad message: PointCloud2"), "{}", skipped.kind);
        live.add_sensor(0, cloud(1.5), t0).expect("decodes");
        let frames = live.ready(t0);
        let placed: Vec<(usize, f64)> =
            frames.iter().map(|(k, f)| (*k, f.as_ref().expect("placed").t_world_sensor.translation.x)).collect();
        // In arrival order, each at the body's 2.0 m plus its own mount.
        assert_eq!(placed.len(), 2);
        assert!(placed[0].0 == 1 && (placed[0].1 - 2.5).abs() < 1e-12, "{placed:?}");
        assert!(placed[1].0 == 0 && (placed[1].1 - 2.25).abs() < 1e-12, "{placed:?}");
    }

    #[test]
    fn a_message_whose_pose_never_comes_is_given_up_after_the_wait() {
        let mut live = LiveFrames::new(opts(), true, 0.5, 10.0);
        let t0 = Instant::now();
        live.add_pose(&tf("map", "base_link", 1.0, 1.0), false).expect("pose");
        live.add_sensor(0, cloud(3.0), t0).expect("decodes");
        assert!(live.ready(t0 + Duration::from_millis(100)).is_empty());
        let out = live.ready(t0 + Duration::from_millis(600));
        let skipped = out[0].1.as_ref().expect_err("no pose");
        assert_eq!(skipped.kind, "missing transform");
        assert!(skipped.reason.contains("lidar"), "{}", skipped.reason);
    }

    #[test]
    fn at_startup_a_message_waits_for_its_transform_until_the_window_ends() {
        let t0 = Instant::now();
        let mut live = LiveFrames::new(opts(), true, 0.5, 10.0).with_startup(t0, 2.0);
        // Discovery: the cloud comes 1.5 s before the first transforms.
        live.add_sensor(0, cloud(1.0), t0).expect("decodes");
        assert!(
            live.ready(t0 + Duration::from_millis(1500)).is_empty(),
            "kept past pose_wait_s during the startup window"
        );
        live.add_pose(&tf("base_link", "lidar", 0.0, 0.25), true).expect("static");
        live.add_pose(&tf("map", "base_link", 0.5, 1.0), false).expect("pose");
        live.add_pose(&tf("map", "base_link", 1.5, 1.0), false).expect("pose");
        let frames = live.ready(t0 + Duration::from_millis(1600));
        assert_eq!(frames.len(), 1);
        let frame = frames[0].1.as_ref().expect("placed once its transform came");
        assert!((frame.t_world_sensor.translation.vector - Vector3::new(1.25, 0.0, 0.0)).norm() < 1e-12);

        // Ten messages with no transform: the newest few wait, the older are given up.
        let mut live = LiveFrames::new(opts(), true, 0.5, 10.0).with_startup(t0, 2.0);
        for i in 0..10 {
            live.add_sensor(0, cloud(f64::from(i)), t0).expect("decodes");
        }
        let out = live.ready(t0 + Duration::from_millis(600));
        assert_eq!(out.len(), 10 - MAX_STARTUP_WAITING);
        assert!(out.iter().all(|(_, r)| r.as_ref().is_err_and(|s| s.kind == "missing transform")));
        assert_eq!(live.pending(), MAX_STARTUP_WAITING);
        // After the window, the per-message wait alone applies.
        assert_eq!(live.ready(t0 + Duration::from_millis(2000)).len(), MAX_STARTUP_WAITING);
        live.add_sensor(0, cloud(20.0), t0 + Duration::from_millis(2000)).expect("decodes");
        assert!(live.ready(t0 + Duration::from_millis(2400)).is_empty());
        assert_eq!(live.ready(t0 + Duration::from_millis(2500)).len(), 1);
    }

    #[test]
    fn a_bad_message_and_a_full_queue_are_skipped_with_their_kind() {
        let mut live = LiveFrames::new(opts(), true, 10.0, 10.0);
        let t0 = Instant::now();
        let mut bad = PointCloud2::from_points(Header::default(), &[[1.0, 0.0, 0.0]]);
        bad.point_step = 7;
        assert_eq!(
            live.add_sensor(0, Message::PointCloud2(bad), t0).expect_err("bad step").kind,
            "bad message: PointCloud2 point_step < its fields"
        );
        for i in 0..MAX_PENDING {
            live.add_sensor(0, cloud(i as f64), t0).expect("queued");
        }
        assert_eq!(live.add_sensor(0, cloud(99.0), t0).expect_err("full").kind, "pose queue full");
        assert_eq!(live.pending(), MAX_PENDING);
    }

    #[test]
    fn each_malformation_has_its_own_kind() {
        use edtmap_ros::msg::{Image, LaserScanMsg};
        let good = PointCloud2::from_points(Header::default(), &[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        let cloud = |f: &dyn Fn(&mut PointCloud2)| {
            let mut c = good.clone();
            f(&mut c);
            Message::PointCloud2(c)
        };
        let image = |encoding: &str, width: u32, step: u32, bytes: usize| {
            Message::Image(Image {
                header: Header::default(),
                height: 2,
                width,
                encoding: encoding.into(),
                is_bigendian: false,
                step,
                data: vec![0; bytes],
            })
        };
        let scan = |ranges: Vec<f32>, angle_increment: f32| {
            Message::LaserScan(LaserScanMsg {
                header: Header::default(),
                angle_min: 0.0,
                angle_max: 1.0,
                angle_increment,
                time_increment: 0.0,
                scan_time: 0.0,
                range_min: 0.1,
                range_max: 10.0,
                ranges,
                intensities: Vec::new(),
            })
        };
        let bad = [
            cloud(&|c| c.fields.clear()),
            cloud(&|c| c.fields[0].datatype = 99),
            cloud(&|c| c.point_step = 7),
            cloud(&|c| c.row_step = 1),
            cloud(&|c| c.data.truncate(5)),
            image("rgb8", 2, 4, 8),
            image("16UC1", 0, 4, 8),
            image("16UC1", 2, 3, 8),
            image("16UC1", 2, 4, 7),
            scan(Vec::new(), 0.1),
            scan(vec![1.0; 4], 0.0),
        ];
        let mut live = LiveFrames::new(opts(), true, 0.5, 10.0);
        let kinds: Vec<&str> =
            bad.into_iter().map(|m| live.add_sensor(0, m, Instant::now()).expect_err("malformed").kind).collect();
        let distinct: std::collections::BTreeSet<&str> = kinds.iter().copied().collect();
        assert_eq!(distinct.len(), kinds.len(), "{kinds:?}");
        assert!(
            kinds.iter().all(|k| k.starts_with("bad message: ")
                && *k != "bad message: other"
                && *k != "bad message: LaserScan other"),
            "{kinds:?}"
        );
    }

    #[test]
    fn without_a_configured_world_frame_outputs_take_the_poses_frame() {
        let t0 = Instant::now();
        let odom = |t: f64| {
            Message::Odometry(StampedTransform {
                header: Header { stamp_ns: (t * 1e9) as i64, frame_id: "odom".into() },
                child_frame: "base_link".into(),
                transform: Isometry3::identity(),
            })
        };
        let mut topic =
            LiveFrames::new(RosOptions { pose_topic: "/odom".into(), world_frame: None, ..opts() }, false, 0.5, 10.0);
        assert_eq!(topic.world_frame(), None);
        topic.add_pose(&odom(0.0), false).expect("pose");
        topic.add_pose(&odom(1.0), false).expect("pose");
        topic.add_sensor(0, cloud(0.5), t0).expect("decodes");
        assert!(topic.ready(t0)[0].1.is_ok());
        assert_eq!(topic.world_frame(), Some("odom"));

        let mut tree = LiveFrames::new(RosOptions { world_frame: None, ..opts() }, true, 0.5, 10.0);
        tree.add_pose(&tf("base_link", "lidar", 0.0, 0.25), true).expect("static");
        tree.add_pose(&tf("odom", "base_link", 0.0, 0.0), false).expect("pose");
        tree.add_pose(&tf("odom", "base_link", 1.0, 0.0), false).expect("pose");
        tree.add_sensor(0, cloud(0.5), t0).expect("decodes");
        assert!(tree.ready(t0)[0].1.is_ok());
        assert_eq!(tree.world_frame(), Some("odom"));

        let mut configured = LiveFrames::new(
            RosOptions { pose_topic: "/odom".into(), world_frame: Some("/map".into()), ..opts() },
            false,
            0.5,
            10.0,
        );
        let map = |t: f64| {
            Message::Odometry(StampedTransform {
                header: Header { stamp_ns: (t * 1e9) as i64, frame_id: "map".into() },
                child_frame: "base_link".into(),
                transform: Isometry3::identity(),
            })
        };
        configured.add_pose(&map(0.0), false).expect("pose");
        configured.add_pose(&map(1.0), false).expect("pose");
        configured.add_sensor(0, cloud(0.5), t0).expect("decodes");
        assert!(configured.ready(t0)[0].1.is_ok());
        assert_eq!(configured.world_frame(), Some("map"));
    }

    #[test]
    fn history_is_bounded() {
        let mut live = LiveFrames::new(opts(), true, 0.5, 2.0);
        for i in 0..100 {
            live.add_pose(&tf("map", "base_link", f64::from(i) * 0.1, 0.0), false).expect("pose");
        }
        let Poses::Tf(tree, _) = &live.poses else { panic!("tf") };
        // 2 s of samples at 10 Hz, plus the one before.
        assert!(tree.samples() <= 22, "{}", tree.samples());
    }
}
