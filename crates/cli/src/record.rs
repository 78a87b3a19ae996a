//! `edtmap record`: a built-in scene written as a ROS 1 bag or ROS 2 MCAP
//! file, with the config that replays it, so the recording path can be
//! tried (and checked) without a robot.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use edtmap::sensor::{DepthData, Frame, Measurement, Sensor};
use edtmap_ros::msg::{CameraInfo, Header, Image, LaserScanMsg, Message, PointCloud2, StampedTransform};
use edtmap_ros::{Encoding, RecordingWriter};
use edtmap_sim::Scene;
use nalgebra::Isometry3;

use crate::interrupt::{self, Interrupted, OnFirst};
use crate::scenes::builtin_config;
use crate::source::build_scene;

/// Arguments of `edtmap record`.
#[derive(Args, Debug, Clone)]
pub(crate) struct RecordArgs {
    /// Built-in scene: uav_pillars, ugv_corridor, room or planar (default:
    /// the `--config`'s `[scene]`).
    #[arg(long)]
    scene: Option<String>,
    /// A config with the scene's sensors: one `[sensor]`, or several
    /// `[[sensors]]` each recorded on its own topics (default: the scene's
    /// built-in config).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Frames to record (default: the scene's length; the scene's path
    /// repeats, so any number can be recorded, disk space allowing).
    #[arg(long)]
    frames: Option<usize>,
    /// Replace an existing NAME.toml beside the recording.
    #[arg(long)]
    force: bool,
    /// The recording: NAME.bag (ROS 1) or NAME.mcap (ROS 2); NAME.toml is
    /// written beside it.
    out: PathBuf,
}

/// Topics of a recorded scene.
const ODOM: &str = "/odom";
const TF: &str = "/tf";

/// Writes the scene's frames, their poses on `/odom` and `/tf`, and the
/// config that replays them.
pub(crate) fn record(args: &RecordArgs) -> Result<()> {
    let (text, origin) = match &args.config {
        Some(path) => (edtmap::config::read(path)?, path.display().to_string()),
        None => {
            let scene = args.scene.as_deref().context("give --scene NAME (or a --config with a [scene] section)")?;
            let text = builtin_config(scene).with_context(|| format!("unknown scene {scene:?}"))?;
            (text.to_string(), format!("built-in configs/{scene}.toml"))
        }
    };
    let (config, sections) = crate::sections::parse(&text, &origin)?;
    let scene_name = match (&args.scene, &sections.scene) {
        (Some(name), _) => name.clone(),
        (None, Some(section)) => section.name.clone(),
        (None, None) => bail!("{origin} has no [scene] section: give --scene NAME"),
    };
    let sensors: Vec<Recorded> = config
        .mapper_sensors()?
        .into_iter()
        .map(|(s, mount)| Recorded::new(s.name, s.sensor, mount, config.other_sensors.is_empty()))
        .collect();
    let (scene, n) = build_scene(&scene_name, sections.scene.as_ref())?;
    let frames = args.frames.unwrap_or(n);
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let config_path = args.out.with_extension("toml");
    check_outputs(args, &config_path)?;
    let first = frame_messages(&scene, &sensors, 0)?;
    check_disk(args, &scene_name, frames, &first)?;
    let mut writer = RecordingWriter::create(&args.out)?;
    if sensors.len() > 1 {
        writer.write(TF_STATIC, &mounts(&scene, &sensors), 0)?;
    }
    let dir = args.out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    interrupt::catch(OnFirst::Finish, &[dir]);
    let mut written = frames;
    for i in 0..frames {
        if interrupt::requested().is_some() {
            written = i;
            break;
        }
        let messages = if i == 0 { first.clone() } else { frame_messages(&scene, &sensors, i)? };
        for (topic, msg, log_ns) in &messages {
            writer.write(topic, msg, *log_ns)?;
        }
    }
    writer.finish()?;
    edtmap_io::files::write_atomic(
        &config_path,
        replay_config(&text, &scene, &sensors, args, &scene_name)?.as_bytes(),
    )?;
    let topics: Vec<&str> = sensors.iter().map(|s| s.topic.as_str()).collect();
    outln!("wrote {} ({written} frames on {}, poses on {ODOM} and {TF})", args.out.display(), topics.join(", "));
    outln!(
        "wrote {}: edtmap run --config {} --dataset {}",
        config_path.display(),
        config_path.display(),
        args.out.display()
    );
    match interrupt::requested() {
        Some(signal) if written < frames => Err(Interrupted {
            signal,
            what: format!("the recording holds the first {written} of {frames} frames, closed and replayable"),
        }
        .into()),
        _ => Ok(()),
    }
}

/// A sensor being recorded: its model, mount and topics.
struct Recorded {
    name: String,
    sensor: Sensor,
    /// `T_body_sensor` as the config gives it (x forward, y left, z up).
    mount: Isometry3<f64>,
    /// The measurement's topic.
    topic: String,
    /// A depth camera's camera info topic.
    info_topic: String,
    /// The frame its messages are in: `sensor` for a lone sensor, whose
    /// poses on `/odom` are the sensor's own; else its name, below `base_link`.
    frame: String,
}

impl Recorded {
    /// A lone sensor keeps the topics a single-sensor recording always had;
    /// one of several is recorded under its name (`/front_camera/depth/image`).
    fn new(name: String, sensor: Sensor, mount: Isometry3<f64>, lone: bool) -> Self {
        let (topic, info_topic, frame) = if lone {
            (sensor_topic(&sensor).to_string(), "/camera/depth/camera_info".to_string(), "sensor".to_string())
        } else {
            let leaf = match &sensor {
                Sensor::Depth(_) => "depth/image",
                Sensor::Planar => "scan",
                Sensor::Lidar(_) | Sensor::Points(_) => "points",
            };
            (format!("/{name}/{leaf}"), format!("/{name}/depth/camera_info"), name.clone())
        };
        Recorded { name, sensor, mount, topic, info_topic, frame }
    }

    /// `T_body_frame`: where the frame the measurement is given in sits on
    /// the robot (a depth camera's optical frame turned from its mount).
    fn in_body(&self, scene: &Scene) -> Isometry3<f64> {
        scene.body_pose(0.0).inverse() * scene.mounted_pose(&self.sensor, &self.mount, 0.0)
    }
}

/// Topics of a recorded scene with several sensors: the sensors' mounts.
const TF_STATIC: &str = "/tf_static";
/// The robot's frame in a recording of several sensors.
const BODY: &str = "base_link";

/// The sensors' mounts on `/tf_static`, `base_link` to each sensor's frame.
fn mounts(scene: &Scene, sensors: &[Recorded]) -> Message {
    let mount = |s: &Recorded| StampedTransform {
        header: header(0, BODY),
        child_frame: s.frame.clone(),
        transform: s.in_body(scene),
    };
    Message::Tf(sensors.iter().map(mount).collect())
}

/// The messages of time step `i`: the pose on `/odom` and `/tf` (a lone
/// sensor's own; the robot's with several sensors), then each sensor's
/// camera info (a depth camera) and measurement; each with its log time.
fn frame_messages(scene: &Scene, sensors: &[Recorded], i: usize) -> Result<Vec<(String, Message, u64)>> {
    let mut out = Vec::new();
    for (k, s) in sensors.iter().enumerate() {
        let frame = scene
            .mounted_frame(&s.sensor, &s.mount, i)
            .with_context(|| format!("simulating frame {i} of {}", s.name))?;
        let stamp_ns = (frame.stamp_s * 1e9).round() as i64;
        let log_ns = u64::try_from(stamp_ns).unwrap_or(0);
        if k == 0 {
            let pose = match sensors {
                [_] => StampedTransform {
                    header: header(stamp_ns, "map"),
                    child_frame: "sensor".into(),
                    transform: frame.t_world_sensor,
                },
                _ => StampedTransform {
                    header: header(stamp_ns, "map"),
                    child_frame: BODY.into(),
                    transform: scene.body_pose(frame.stamp_s),
                },
            };
            out.push((ODOM.to_string(), Message::Odometry(pose.clone()), log_ns));
            out.push((TF.to_string(), Message::Tf(vec![pose]), log_ns));
        }
        if let Sensor::Depth(c) = &s.sensor {
            let k = [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0];
            let info = CameraInfo::pinhole(header(stamp_ns, &s.frame), c.width, c.height, k);
            out.push((s.info_topic.clone(), Message::CameraInfo(info), log_ns));
        }
        out.push((s.topic.clone(), sensor_message(&s.sensor, &frame, header(stamp_ns, &s.frame))?, log_ns));
    }
    Ok(out)
}

/// Refuses to replace a replay config the user did not ask to replace, or
/// to write through links.
fn check_outputs(args: &RecordArgs, config_path: &Path) -> Result<()> {
    edtmap_io::files::check_output(&args.out)?;
    edtmap_io::files::check_output(config_path)?;
    if config_path.exists() && !args.force {
        bail!(
            "{} exists and would be replaced by the config that replays {}: remove it, record under another name, or pass --force",
            config_path.display(),
            args.out.display()
        );
    }
    Ok(())
}

/// Refuses a recording that would not fit on its disk, estimated from
/// the first frame's messages (with 10 % for the container's records).
fn check_disk(args: &RecordArgs, scene: &str, frames: usize, first: &[(String, Message, u64)]) -> Result<()> {
    let encoding = if args.out.extension().is_some_and(|e| e == "bag") { Encoding::Ros1 } else { Encoding::Cdr };
    let per_frame: u64 = first.iter().map(|(t, m, _)| (m.encode(encoding).len() + t.len() + 64) as u64).sum();
    let needed = per_frame.saturating_mul(frames as u64).saturating_mul(11) / 10;
    let dir = args.out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Some(free) = edtmap_io::files::free_space(dir) {
        if needed > free {
            bail!(
                "{frames} frames of {scene} would take about {} and {} has {} free: ask for fewer --frames",
                edtmap::memory::format_bytes(needed),
                dir.display(),
                edtmap::memory::format_bytes(free)
            );
        }
    }
    Ok(())
}

fn header(stamp_ns: i64, frame: &str) -> Header {
    Header { stamp_ns, frame_id: frame.into() }
}

fn sensor_topic(sensor: &Sensor) -> &'static str {
    match sensor {
        Sensor::Depth(_) => "/camera/depth/image",
        Sensor::Planar => "/scan",
        Sensor::Lidar(_) | Sensor::Points(_) => "/points",
    }
}

/// The frame's measurement as the ROS message a driver would publish.
fn sensor_message(sensor: &Sensor, frame: &Frame, h: Header) -> Result<Message> {
    Ok(match (&frame.measurement, sensor) {
        (Measurement::Depth(img), _) => {
            let (encoding, bytes, data): (&str, u32, Vec<u8>) = match &img.data {
                DepthData::Metres(v) => ("32FC1", 4, v.iter().flat_map(|d| d.to_le_bytes()).collect()),
                DepthData::U16 { values, .. } => ("16UC1", 2, values.iter().flat_map(|d| d.to_le_bytes()).collect()),
            };
            Message::Image(Image {
                header: h,
                height: img.height,
                width: img.width,
                encoding: encoding.into(),
                is_bigendian: false,
                step: img.width * bytes,
                data,
            })
        }
        (Measurement::Lidar(scan), Sensor::Lidar(lidar)) => {
            let bins = lidar.azimuth_bins;
            let points = scan.ranges.iter().enumerate().map(|(i, &r)| {
                let ok = r.is_finite() && r >= lidar.range.min_m && r <= lidar.range.max_m;
                if ok {
                    lidar.direction(i / bins, i % bins).map(|c| c as f32 * r)
                } else {
                    [f32::NAN; 3]
                }
            });
            Message::PointCloud2(PointCloud2::from_points(h, &points.collect::<Vec<_>>()))
        }
        (Measurement::Points(c), _) => Message::PointCloud2(PointCloud2::from_points(h, &c.points)),
        (Measurement::Scan(s), _) => {
            let n = s.ranges.len().saturating_sub(1) as f64;
            Message::LaserScan(LaserScanMsg {
                header: h,
                angle_min: s.angle_min_rad as f32,
                angle_max: (s.angle_min_rad + n * s.angle_increment_rad) as f32,
                angle_increment: s.angle_increment_rad as f32,
                time_increment: 0.0,
                scan_time: 0.0,
                range_min: s.range.min_m,
                range_max: s.range.max_m,
                ranges: s.ranges.clone(),
                intensities: Vec::new(),
            })
        }
        (m, _) => bail!("a {} from a {} cannot be recorded", m.kind(), sensor.kind()),
    })
}

/// A spinning LiDAR's sensor table as a recording replays it: its range
/// images were written as point clouds, cast as rays.
fn as_points(table: &mut toml::Table) {
    if table.get("kind").and_then(|k| k.as_str()) == Some("lidar") {
        for key in ["rings", "elevation_min_deg", "elevation_max_deg", "ring_elevations_deg", "azimuth_bins"] {
            table.remove(key);
        }
        table.insert("kind".into(), "points".into());
        table.insert("construction".into(), "raycast".into());
    }
}

/// The scene's config without `[scene]`, with the recording's topics; a
/// spinning LiDAR's range images become point clouds, cast as rays. With
/// several sensors, each `[[sensors]]` entry gets its topic and the mount
/// of its messages' frame.
fn replay_config(text: &str, scene: &Scene, sensors: &[Recorded], args: &RecordArgs, name: &str) -> Result<String> {
    let mut table: toml::Table = text.parse().context("config")?;
    table.remove("scene");
    let mut dataset = toml::Table::new();
    if let Some(toml::Value::Table(s)) = table.get_mut("sensor") {
        as_points(s);
        dataset.insert("sensor_topic".into(), sensors[0].topic.clone().into());
    }
    if let Some(toml::Value::Array(entries)) = table.get_mut("sensors") {
        for (entry, s) in entries.iter_mut().zip(sensors) {
            let toml::Value::Table(entry) = entry else { continue };
            as_points(entry);
            entry.insert("topic".into(), s.topic.clone().into());
            if sensors.len() == 1 {
                // The poses on `/odom` are the lone sensor's own.
                entry.remove("sensor_in_body");
                continue;
            }
            let pose = s.in_body(scene);
            let (t, q) = (pose.translation.vector, pose.rotation.quaternion());
            let values = [t.x, t.y, t.z, q.i, q.j, q.k, q.w].map(toml::Value::from);
            entry.insert("sensor_in_body".into(), toml::Value::Array(values.to_vec()));
        }
    }
    dataset.insert("pose_topic".into(), ODOM.into());
    table.insert("dataset".into(), toml::Value::Table(dataset));
    let body = toml::to_string(&table).context("config")?;
    Ok(format!(
        "# Replays {} (edtmap record --scene {name}):\n# edtmap run --config THIS --dataset {}\n\n{body}",
        args.out.display(),
        args.out.display()
    ))
}
