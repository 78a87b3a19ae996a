//! The ROS message types edtmap maps from, decoded from (and encoded to)
//! either wire format with one description per type.
//!
//! Sensors: `sensor_msgs/PointCloud2`, `sensor_msgs/Image` (depth:
//! `16UC1`/`mono16` scaled to metres, or `32FC1` metres) with
//! `sensor_msgs/CameraInfo`, and `sensor_msgs/LaserScan`. Poses:
//! `nav_msgs/Odometry`, `geometry_msgs/PoseStamped`,
//! `geometry_msgs/TransformStamped` and `tf2_msgs/TFMessage` (ROS 1's
//! `tf/tfMessage` too). Fields after the last one edtmap uses (an
//! odometry's twist) are not read.
//!
//! The sensor messages are also what the live node sends and receives over
//! DDS: they derive serde in ROS 2 IDL order (CDR is positional), with the
//! header as `builtin_interfaces/Time` and frame, so one struct serves a
//! recording and a live topic.

use super::wire::{WireReader, WireResult, WireWriter};
use super::Encoding;
use nalgebra::{Isometry3, Quaternion, Translation3};
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch.
    pub fn from_ns(ns: i64) -> Self {
        Time { sec: ns.div_euclid(1_000_000_000) as i32, nanosec: ns.rem_euclid(1_000_000_000) as u32 }
    }

    /// Nanoseconds since the epoch.
    pub fn ns(&self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// `std_msgs/Header` as ROS 2 IDL lays it out.
#[derive(Serialize, Deserialize)]
struct IdlHeader {
    stamp: Time,
    frame_id: String,
}

impl From<IdlHeader> for Header {
    fn from(h: IdlHeader) -> Self {
        Header { stamp_ns: h.stamp.ns(), frame_id: h.frame_id }
    }
}

impl From<Header> for IdlHeader {
    fn from(h: Header) -> Self {
        IdlHeader { stamp: Time::from_ns(h.stamp_ns), frame_id: h.frame_id }
    }
}

/// A message header: time stamp and coordinate frame.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(from = "IdlHeader", into = "IdlHeader")]
pub struct Header {
    /// Stamp, nanoseconds since the epoch.
    pub stamp_ns: i64,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

impl Header {
    /// The stamp in seconds.
    pub fn stamp_s(&self) -> f64 {
        self.stamp_ns as f64 * 1e-9
    }

    fn read(r: &mut WireReader<'_>) -> WireResult<Self> {
        let stamp_ns = if r.is_ros1() {
            r.u32("header.seq")?;
            let s = r.u32("header.stamp.secs")?;
            let ns = r.u32("header.stamp.nsecs")?;
            i64::from(s) * 1_000_000_000 + i64::from(ns)
        } else {
            let s = r.i32("header.stamp.sec")?;
            let ns = r.u32("header.stamp.nanosec")?;
            i64::from(s) * 1_000_000_000 + i64::from(ns)
        };
        Ok(Header { stamp_ns, frame_id: r.string("header.frame_id")? })
    }

    fn write(&self, w: &mut WireWriter) {
        let (s, ns) = (self.stamp_ns.div_euclid(1_000_000_000), self.stamp_ns.rem_euclid(1_000_000_000) as u32);
        if w.is_ros1() {
            w.u32(0);
            w.u32(s as u32);
        } else {
            w.i32(s as i32);
        }
        w.u32(ns);
        w.string(&self.frame_id);
    }
}

/// One field of a [`PointCloud2`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PointField {
    /// Field name (`x`, `y`, `z`, `intensity`, ...).
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// Type code: 1 int8, 2 uint8, 3 int16, 4 uint16, 5 int32, 6 uint32,
    /// 7 float32, 8 float64.
    pub datatype: u8,
    /// Elements in the field.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Stamp and frame.
    pub header: Header,
    /// Rows (1 for unordered clouds).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The fields of a point.
    pub fields: Vec<PointField>,
    /// Byte order of `data`.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    /// Whether every point is finite.
    pub is_dense: bool,
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Image {
    /// Stamp and frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`16UC1`, `32FC1`, `mono16`, ...).
    pub encoding: String,
    /// Byte order of multi-byte pixels (a `uint8` in the message).
    #[serde(with = "flag")]
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    /// The pixels.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// A `uint8` field read as a flag (any value but 0 is true).
mod flag {
    use serde::{Deserialize, Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer>(v: &bool, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(u8::from(*v))
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
        Ok(u8::deserialize(d)? != 0)
    }
}

/// `sensor_msgs/RegionOfInterest`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left column.
    pub x_offset: u32,
    /// Top row.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Whether to rectify.
    pub do_rectify: bool,
}

/// `sensor_msgs/CameraInfo` (the depth camera model reads the size and
/// `k`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and frame.
    pub header: Header,
    /// Image rows.
    pub height: u32,
    /// Image columns.
    pub width: u32,
    /// Distortion model name (`plumb_bob`, ...).
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Row-major 3 × 3 intrinsic matrix.
    pub k: [f64; 9],
    /// Row-major 3 × 3 rectification.
    pub r: [f64; 9],
    /// Row-major 3 × 4 projection.
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}

impl CameraInfo {
    /// The camera info of an undistorted pinhole camera of intrinsics `k`
    /// (row-major 3 × 3): `plumb_bob` with zero coefficients, no
    /// rectification, the projection `[k | 0]`, no binning, the whole image.
    pub fn pinhole(header: Header, width: u32, height: u32, k: [f64; 9]) -> CameraInfo {
        CameraInfo {
            header,
            height,
            width,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k,
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, k[6], k[7], k[8], 0.0],
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        }
    }
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LaserScanMsg {
    /// Stamp and frame.
    pub header: Header,
    /// Angle of the first beam, radians.
    pub angle_min: f32,
    /// Angle of the last beam, radians.
    pub angle_max: f32,
    /// Angle between beams, radians.
    pub angle_increment: f32,
    /// Time between beams, seconds.
    pub time_increment: f32,
    /// Time between scans, seconds.
    pub scan_time: f32,
    /// Shortest valid range, metres.
    pub range_min: f32,
    /// Longest valid range, metres.
    pub range_max: f32,
    /// Ranges, metres.
    pub ranges: Vec<f32>,
    /// Intensities (may be empty).
    pub intensities: Vec<f32>,
}

/// A stamped rigid transform: `Odometry`, `PoseStamped` or
/// `TransformStamped`, as the pose of `child_frame` in `header.frame_id`.
#[derive(Debug, Clone, PartialEq)]
pub struct StampedTransform {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame whose pose this is (empty for `PoseStamped`).
    pub child_frame: String,
    /// `T_parent_child`.
    pub transform: Isometry3<f64>,
}

/// A decoded message of a type edtmap reads.
// A camera info's matrices make its variant some 300 bytes; messages are
// decoded and used one at a time, so no box (an allocation per message).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// A point cloud.
    PointCloud2(PointCloud2),
    /// An image.
    Image(Image),
    /// Camera intrinsics.
    CameraInfo(CameraInfo),
    /// A planar scan.
    LaserScan(LaserScanMsg),
    /// `nav_msgs/Odometry`.
    Odometry(StampedTransform),
    /// `geometry_msgs/PoseStamped`.
    PoseStamped(StampedTransform),
    /// `geometry_msgs/TransformStamped`.
    TransformStamped(StampedTransform),
    /// `tf2_msgs/TFMessage`: several transforms.
    Tf(Vec<StampedTransform>),
}

/// Message types [`Message::decode`] reads, as `package/Type`.
pub const SUPPORTED_TYPES: [&str; 9] = [
    "sensor_msgs/PointCloud2",
    "sensor_msgs/Image",
    "sensor_msgs/CameraInfo",
    "sensor_msgs/LaserScan",
    "nav_msgs/Odometry",
    "geometry_msgs/PoseStamped",
    "geometry_msgs/TransformStamped",
    "tf2_msgs/TFMessage",
    "tf/tfMessage",
];

impl Message {
    /// Decodes a message of type `msg_type` (`package/Type`); the error
    /// names the type and the field.
    pub fn decode(msg_type: &str, data: &[u8], encoding: Encoding) -> Result<Message, String> {
        let mut r = WireReader::new(data, encoding)?;
        let r = &mut r;
        let msg = match msg_type {
            "sensor_msgs/PointCloud2" => read_cloud(r).map(Message::PointCloud2),
            "sensor_msgs/Image" => read_image(r).map(Message::Image),
            "sensor_msgs/CameraInfo" => read_camera_info(r).map(Message::CameraInfo),
            "sensor_msgs/LaserScan" => read_scan(r).map(Message::LaserScan),
            "nav_msgs/Odometry" => read_odometry(r).map(Message::Odometry),
            "geometry_msgs/PoseStamped" => read_pose_stamped(r).map(Message::PoseStamped),
            "geometry_msgs/TransformStamped" => read_transform_stamped(r).map(Message::TransformStamped),
            "tf2_msgs/TFMessage" | "tf/tfMessage" => read_tf(r).map(Message::Tf),
            other => {
                return Err(format!("message type {other} is not one edtmap reads ({})", SUPPORTED_TYPES.join(", ")))
            }
        }
        .map_err(|e| format!("{msg_type}: {e}"))?;
        Ok(msg)
    }

    /// Encodes the message (CDR little-endian for [`Encoding::Cdr`]).
    pub fn encode(&self, encoding: Encoding) -> Vec<u8> {
        let mut w = WireWriter::new(encoding);
        let w_ = &mut w;
        match self {
            Message::PointCloud2(m) => write_cloud(w_, m),
            Message::Image(m) => write_image(w_, m),
            Message::CameraInfo(m) => write_camera_info(w_, m),
            Message::LaserScan(m) => write_scan(w_, m),
            Message::Odometry(m) => write_odometry(w_, m),
            Message::PoseStamped(m) => write_pose_stamped(w_, m),
            Message::TransformStamped(m) => write_transform_stamped(w_, m),
            Message::Tf(ts) => {
                w_.seq_len(ts.len());
                ts.iter().for_each(|t| write_transform_stamped(w_, t));
            }
        }
        w.finish()
    }

    /// The message's `package/Type` name.
    pub fn type_name(&self) -> &'static str {
        match self {
            Message::PointCloud2(_) => SUPPORTED_TYPES[0],
            Message::Image(_) => SUPPORTED_TYPES[1],
            Message::CameraInfo(_) => SUPPORTED_TYPES[2],
            Message::LaserScan(_) => SUPPORTED_TYPES[3],
            Message::Odometry(_) => SUPPORTED_TYPES[4],
            Message::PoseStamped(_) => SUPPORTED_TYPES[5],
            Message::TransformStamped(_) => SUPPORTED_TYPES[6],
            Message::Tf(_) => SUPPORTED_TYPES[7],
        }
    }
}

fn read_cloud(r: &mut WireReader<'_>) -> WireResult<PointCloud2> {
    let header = Header::read(r)?;
    let (height, width) = (r.u32("height")?, r.u32("width")?);
    let n = r.seq_len("fields", 13)?;
    let mut fields = Vec::with_capacity(n);
    for _ in 0..n {
        fields.push(PointField {
            name: r.string("fields.name")?,
            offset: r.u32("fields.offset")?,
            datatype: r.u8("fields.datatype")?,
            count: r.u32("fields.count")?,
        });
    }
    let is_bigendian = r.u8("is_bigendian")? != 0;
    let (point_step, row_step) = (r.u32("point_step")?, r.u32("row_step")?);
    let data = r.bytes("data")?;
    let is_dense = r.u8("is_dense")? != 0;
    Ok(PointCloud2 { header, height, width, fields, is_bigendian, point_step, row_step, data, is_dense })
}

fn write_cloud(w: &mut WireWriter, m: &PointCloud2) {
    m.header.write(w);
    w.u32(m.height);
    w.u32(m.width);
    w.seq_len(m.fields.len());
    for f in &m.fields {
        w.string(&f.name);
        w.u32(f.offset);
        w.u8(f.datatype);
        w.u32(f.count);
    }
    w.u8(m.is_bigendian.into());
    w.u32(m.point_step);
    w.u32(m.row_step);
    w.bytes(&m.data);
    w.u8(m.is_dense.into());
}

fn read_image(r: &mut WireReader<'_>) -> WireResult<Image> {
    let header = Header::read(r)?;
    let (height, width) = (r.u32("height")?, r.u32("width")?);
    let encoding = r.string("encoding")?;
    let is_bigendian = r.u8("is_bigendian")? != 0;
    let step = r.u32("step")?;
    Ok(Image { header, height, width, encoding, is_bigendian, step, data: r.bytes("data")? })
}

fn write_image(w: &mut WireWriter, m: &Image) {
    m.header.write(w);
    w.u32(m.height);
    w.u32(m.width);
    w.string(&m.encoding);
    w.u8(m.is_bigendian.into());
    w.u32(m.step);
    w.bytes(&m.data);
}

fn read_camera_info(r: &mut WireReader<'_>) -> WireResult<CameraInfo> {
    let header = Header::read(r)?;
    let (height, width) = (r.u32("height")?, r.u32("width")?);
    let distortion_model = r.string("distortion_model")?;
    let d = r.f64s("d")?;
    let k = r.f64_array::<9>("k")?;
    let (r_, p) = (r.f64_array::<9>("r")?, r.f64_array::<12>("p")?);
    let (binning_x, binning_y) = (r.u32("binning_x")?, r.u32("binning_y")?);
    let roi = RegionOfInterest {
        x_offset: r.u32("roi.x_offset")?,
        y_offset: r.u32("roi.y_offset")?,
        height: r.u32("roi.height")?,
        width: r.u32("roi.width")?,
        do_rectify: r.u8("roi.do_rectify")? != 0,
    };
    Ok(CameraInfo { header, height, width, distortion_model, d, k, r: r_, p, binning_x, binning_y, roi })
}

fn write_camera_info(w: &mut WireWriter, m: &CameraInfo) {
    m.header.write(w);
    w.u32(m.height);
    w.u32(m.width);
    w.string(&m.distortion_model);
    w.f64s(&m.d);
    w.f64_array(&m.k);
    w.f64_array(&m.r);
    w.f64_array(&m.p);
    let roi = &m.roi;
    for v in [m.binning_x, m.binning_y, roi.x_offset, roi.y_offset, roi.height, roi.width] {
        w.u32(v);
    }
    w.u8(roi.do_rectify.into());
}

fn read_scan(r: &mut WireReader<'_>) -> WireResult<LaserScanMsg> {
    let header = Header::read(r)?;
    let mut v = [0f32; 7];
    for (x, name) in v.iter_mut().zip([
        "angle_min",
        "angle_max",
        "angle_increment",
        "time_increment",
        "scan_time",
        "range_min",
        "range_max",
    ]) {
        *x = r.f32(name)?;
    }
    let [angle_min, angle_max, angle_increment, time_increment, scan_time, range_min, range_max] = v;
    let ranges = r.f32s("ranges")?;
    let intensities = r.f32s("intensities")?;
    Ok(LaserScanMsg {
        header,
        angle_min,
        angle_max,
        angle_increment,
        time_increment,
        scan_time,
        range_min,
        range_max,
        ranges,
        intensities,
    })
}

fn write_scan(w: &mut WireWriter, m: &LaserScanMsg) {
    m.header.write(w);
    for x in [m.angle_min, m.angle_max, m.angle_increment, m.time_increment, m.scan_time, m.range_min, m.range_max] {
        w.f32(x);
    }
    w.f32s(&m.ranges);
    w.f32s(&m.intensities);
}

/// A `geometry_msgs/Pose` or `Transform`: translation then quaternion.
fn read_rigid(r: &mut WireReader<'_>, what: &str) -> WireResult<Isometry3<f64>> {
    let t = r.f64_array::<3>(what)?;
    let q = r.f64_array::<4>(what)?;
    rigid(t, q, what)
}

/// The rigid transform of a translation and a quaternion `[x, y, z, w]`,
/// as every pose message gives them; `what` names it in the error.
pub fn rigid(t: [f64; 3], [x, y, z, w]: [f64; 4], what: &str) -> WireResult<Isometry3<f64>> {
    if t.iter().any(|v| !v.is_finite()) {
        return Err(format!("{what}: translation {t:?} is not finite"));
    }
    // The rule every front end applies: normalised within the tolerance
    // (stored unit quaternions kept bit for bit), refused beyond it.
    let (rotation, _) =
        edtmap::sensor::rotation_from_quaternion(Quaternion::new(w, x, y, z)).map_err(|e| format!("{what}: {e}"))?;
    Ok(Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), rotation))
}

fn write_rigid(w: &mut WireWriter, p: &Isometry3<f64>) {
    w.f64_array(p.translation.vector.as_slice());
    let q = p.rotation.quaternion();
    w.f64_array(&[q.i, q.j, q.k, q.w]);
}

fn read_odometry(r: &mut WireReader<'_>) -> WireResult<StampedTransform> {
    let header = Header::read(r)?;
    let child_frame = r.string("child_frame_id")?;
    let transform = read_rigid(r, "pose.pose")?;
    Ok(StampedTransform { header, child_frame, transform })
}

fn write_odometry(w: &mut WireWriter, m: &StampedTransform) {
    m.header.write(w);
    w.string(&m.child_frame);
    write_rigid(w, &m.transform);
    w.f64_array(&[0.0; 36]); // pose covariance
    w.f64_array(&[0.0; 6 + 36]); // twist and its covariance
}

fn read_pose_stamped(r: &mut WireReader<'_>) -> WireResult<StampedTransform> {
    let header = Header::read(r)?;
    let transform = read_rigid(r, "pose")?;
    Ok(StampedTransform { header, child_frame: String::new(), transform })
}

fn write_pose_stamped(w: &mut WireWriter, m: &StampedTransform) {
    m.header.write(w);
    write_rigid(w, &m.transform);
}

fn read_transform_stamped(r: &mut WireReader<'_>) -> WireResult<StampedTransform> {
    let header = Header::read(r)?;
    let child_frame = r.string("child_frame_id")?;
    let transform = read_rigid(r, "transform")?;
    Ok(StampedTransform { header, child_frame, transform })
}

fn write_transform_stamped(w: &mut WireWriter, m: &StampedTransform) {
    m.header.write(w);
    w.string(&m.child_frame);
    write_rigid(w, &m.transform);
}

fn read_tf(r: &mut WireReader<'_>) -> WireResult<Vec<StampedTransform>> {
    // Smallest TransformStamped: stamp and two empty strings (16 bytes at
    // least), 7 × 8 bytes of numbers.
    let n = r.seq_len("transforms", 72)?;
    (0..n).map(|_| read_transform_stamped(r)).collect()
}
