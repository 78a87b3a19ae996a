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

use crate::interrupt::{self, Interrupted, OnFirst};
use crate::scenes::builtin_config;
use crate::source::build_scene;

/// Arguments of `edtmap record`.
#[derive(Args, Debug, Clone)]
pub(crate) struct RecordArgs {
    /// Built-in scene: uav_pillars, ugv_corridor, room or planar.
    #[arg(long)]
    scene: String,
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
    let text = builtin_config(&args.scene).with_context(|| format!("unknown scene {:?}", args.scene))?;
    let (config, sections) = crate::sections::parse(text, &format!("built-in configs/{}.toml", args.scene))?;
    let (sensor, _) = config.mapper_params()?;
    let (scene, n) = build_scene(&args.scene, sections.scene.as_ref())?;
    let frames = args.frames.unwrap_or(n);
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let config_path = args.out.with_extension("toml");
    check_outputs(args, &config_path)?;
    let topic = sensor_topic(&sensor);
    let first = frame_messages(&scene, &sensor, 0)?;
    check_disk(args, frames, &first)?;
    let mut writer = RecordingWriter::create(&args.out)?;
    let dir = args.out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    interrupt::catch(OnFirst::Finish, &[dir]);
    let mut written = frames;
    for i in 0..frames {
        if interrupt::requested().is_some() {
            written = i;
            break;
        }
        let messages = if i == 0 { first.clone() } else { frame_messages(&scene, &sensor, i)? };
        for (topic, msg, log_ns) in &messages {
            writer.write(topic, msg, *log_ns)?;
        }
    }
    writer.finish()?;
    edtmap_io::files::write_atomic(&config_path, replay_config(text, &sensor, args)?.as_bytes())?;
    outln!("wrote {} ({written} frames on {topic}, poses on {ODOM} and {TF})", args.out.display());
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

/// The messages of frame `i`: its pose on `/odom` and `/tf`, the camera
/// info of a depth camera, and the measurement; each with its log time.
fn frame_messages(scene: &Scene, sensor: &Sensor, i: usize) -> Result<Vec<(&'static str, Message, u64)>> {
    let frame = scene.frame(sensor, i).with_context(|| format!("simulating frame {i}"))?;
    let stamp_ns = (frame.stamp_s * 1e9).round() as i64;
    let log_ns = u64::try_from(stamp_ns).unwrap_or(0);
    let pose = StampedTransform {
        header: header(stamp_ns, "map"),
        child_frame: "sensor".into(),
        transform: frame.t_world_sensor,
    };
    let mut out = vec![(ODOM, Message::Odometry(pose.clone()), log_ns), (TF, Message::Tf(vec![pose]), log_ns)];
    if let Sensor::Depth(c) = sensor {
        let k = [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0];
        let info = CameraInfo::pinhole(header(stamp_ns, "sensor"), c.width, c.height, k);
        out.push(("/camera/depth/camera_info", Message::CameraInfo(info), log_ns));
    }
    out.push((sensor_topic(sensor), sensor_message(sensor, &frame, stamp_ns)?, log_ns));
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
fn check_disk(args: &RecordArgs, frames: usize, first: &[(&str, Message, u64)]) -> Result<()> {
    let encoding = if args.out.extension().is_some_and(|e| e == "bag") { Encoding::Ros1 } else { Encoding::Cdr };
    let per_frame: u64 = first.iter().map(|(t, m, _)| (m.encode(encoding).len() + t.len() + 64) as u64).sum();
    let needed = per_frame.saturating_mul(frames as u64).saturating_mul(11) / 10;
    let dir = args.out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Some(free) = edtmap_io::files::free_space(dir) {
        if needed > free {
            bail!(
                "{frames} frames of {} would take about {} and {} has {} free: ask for fewer --frames",
                args.scene,
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
fn sensor_message(sensor: &Sensor, frame: &Frame, stamp_ns: i64) -> Result<Message> {
    let h = header(stamp_ns, "sensor");
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

/// The scene's config without `[scene]`, with the recording's topics; a
/// spinning LiDAR's range images become point clouds, cast as rays.
fn replay_config(text: &str, sensor: &Sensor, args: &RecordArgs) -> Result<String> {
    let mut table: toml::Table = text.parse().context("built-in config")?;
    table.remove("scene");
    if let (Sensor::Lidar(_), Some(toml::Value::Table(s))) = (sensor, table.get_mut("sensor")) {
        for key in ["rings", "elevation_min_deg", "elevation_max_deg", "ring_elevations_deg", "azimuth_bins"] {
            s.remove(key);
        }
        s.insert("kind".into(), "points".into());
        s.insert("construction".into(), "raycast".into());
    }
    let mut dataset = toml::Table::new();
    dataset.insert("sensor_topic".into(), sensor_topic(sensor).into());
    dataset.insert("pose_topic".into(), ODOM.into());
    table.insert("dataset".into(), toml::Value::Table(dataset));
    let body = toml::to_string(&table).context("config")?;
    Ok(format!(
        "# Replays {} (edtmap record --scene {}):\n# edtmap run --config THIS --dataset {}\n\n{body}",
        args.out.display(),
        args.scene,
        args.out.display()
    ))
}
