//! ROS 2 message and service types as DDS carries them, serialized by
//! `ros2-client`'s CDR serde. The sensor messages are the recordings' own
//! ([`edtmap_ros::msg`], wrapped in [`Dds`]), so a live message meets the
//! same decoding (`PointCloud2::xyz`, `Image::depth`, `LaserScanMsg::scan`)
//! and the same errors as a recorded one. The pose, map, diagnostic and
//! service types are here: one struct per IDL type, fields in IDL order
//! (CDR is positional); pose messages convert into the recordings'
//! `StampedTransform`.

use edtmap_ros::msg;
pub use edtmap_ros::msg::{CameraInfo, Header, Image, LaserScanMsg, PointCloud2, PointField, Time};
use nalgebra::Isometry3;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Marks a type `ros2-client` may publish, take and serve.
macro_rules! messages {
    ($($t:ty),*) => { $(impl ros2_client::Message for $t {})* };
}

/// A message type of the recordings ([`edtmap_ros::msg`]: the sensor
/// messages, which derive serde in ROS 2 IDL order) as `ros2-client`
/// publishes and takes it: the same bytes, the type marked as a message.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Dds<T>(pub T);

impl<T: Serialize + DeserializeOwned> ros2_client::Message for Dds<T> {}

/// `geometry_msgs/Vector3` (and `Point`: the same layout).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Point`.
pub type Point = Vector3;

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

/// `geometry_msgs/Transform` (and `Pose`: the same layout).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation (a pose's position).
    pub translation: Vector3,
    /// Rotation (a pose's orientation).
    pub rotation: Quaternion,
}

/// `geometry_msgs/Pose`.
pub type Pose = Transform;

impl Transform {
    /// The isometry, read as a recorded pose is; a quaternion far from
    /// unit length is an error.
    pub fn isometry(&self) -> Result<Isometry3<f64>, String> {
        let (t, q) = (self.translation, self.rotation);
        msg::rigid([t.x, t.y, t.z], [q.x, q.y, q.z, q.w], "pose")
    }

    /// From an isometry.
    pub fn from_isometry(p: &Isometry3<f64>) -> Self {
        let (t, q) = (p.translation.vector, p.rotation.quaternion());
        Transform {
            translation: Vector3 { x: t.x, y: t.y, z: t.z },
            rotation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w },
        }
    }
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// `T_parent_child`.
    pub transform: Transform,
}

impl From<&msg::StampedTransform> for TransformStamped {
    fn from(t: &msg::StampedTransform) -> Self {
        TransformStamped {
            header: t.header.clone(),
            child_frame_id: t.child_frame.clone(),
            transform: Transform::from_isometry(&t.transform),
        }
    }
}

impl TransformStamped {
    fn stamped(self) -> Result<msg::StampedTransform, String> {
        let transform = self.transform.isometry()?;
        Ok(msg::StampedTransform { header: self.header, child_frame: self.child_frame_id, transform })
    }
}

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6 × 6.
    pub covariance: [[f64; 6]; 6],
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// Linear then angular velocity.
    pub twist: [Vector3; 2],
    /// Row-major 6 × 6.
    pub covariance: [[f64; 6]; 6],
}

/// `nav_msgs/Odometry`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and frame of the pose.
    pub header: Header,
    /// The robot's frame.
    pub child_frame_id: String,
    /// `T_frame_child`.
    pub pose: PoseWithCovariance,
    /// Velocity in the child frame.
    pub twist: TwistWithCovariance,
}

/// `nav_msgs/MapMetaData`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    /// When the map was loaded.
    pub map_load_time: Time,
    /// Metres per cell.
    pub resolution: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Pose of cell (0, 0)'s corner.
    pub origin: Pose,
}

/// `nav_msgs/OccupancyGrid`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Stamp and frame.
    pub header: Header,
    /// Size and placement.
    pub info: MapMetaData,
    /// Row-major cells: -1 unknown, 0 free, 100 occupied.
    pub data: Vec<i8>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    pub level: u8,
    /// Name.
    pub name: String,
    /// Summary.
    pub message: String,
    /// Source.
    pub hardware_id: String,
    /// Values.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// Statuses.
    pub status: Vec<DiagnosticStatus>,
}

/// `edtmap_msgs/GetDistances` request.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetDistancesRequest {
    /// Points in the world frame, metres.
    pub points: Vec<Point>,
    /// Signed distance (negative inside obstacles) instead of the distance
    /// to the nearest obstacle.
    pub signed_distance: bool,
}

/// `edtmap_msgs/GetDistances` response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetDistancesResponse {
    /// Whether the points were answered (false: too many for one call).
    pub success: bool,
    /// Why not, when they were not.
    pub message: String,
    /// Stamp of the latest frame the answers include.
    pub map_stamp: Time,
    /// Distance per point, metres; NaN outside the mapped range.
    pub distances: Vec<f64>,
    /// Gradient of the distance per point.
    pub gradients: Vec<Vector3>,
    /// State per point: 0 outside the map, 1 unknown, 2 free, 3 occupied.
    pub states: Vec<u8>,
    /// Per point: whether a voxel used had no obstacle within the cutoff
    /// (the distance is then a lower bound).
    pub saturated: Vec<bool>,
}

/// `edtmap_msgs/GetEsdfBox` request.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetEsdfBoxRequest {
    /// Lowest corner, metres, world frame.
    pub min_corner: Point,
    /// Highest corner (excluded), metres.
    pub max_corner: Point,
    /// Signed distances (negative inside obstacles).
    pub signed_distance: bool,
}

/// `edtmap_msgs/GetEsdfBox` response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetEsdfBoxResponse {
    /// Whether the box was exported.
    pub success: bool,
    /// Why not, when it was not.
    pub message: String,
    /// Stamp of the latest frame the box includes.
    pub map_stamp: Time,
    /// Centre of the first voxel (lowest x, y, z), metres.
    pub origin: Point,
    /// Voxel edge, metres.
    pub voxel_size: f64,
    /// Voxels along x, y, z.
    pub size: [u32; 3],
    /// Distance per voxel, metres, x fastest; saturated voxels hold the cutoff.
    pub distances: Vec<f32>,
    /// Central-difference gradient per voxel (x, y, z interleaved), zero on
    /// the box's faces along the axis that leaves it.
    pub gradients: Vec<f32>,
    /// State per voxel: 0 outside the map, 1 unknown, 2 free, 3 occupied.
    pub states: Vec<u8>,
}

/// `edtmap_msgs/SaveMap` request.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SaveMapRequest {
    /// Where to write the map (replaced atomically).
    pub path: String,
}

/// `edtmap_msgs/SaveMap` response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SaveMapResponse {
    /// Whether the map was written.
    pub success: bool,
    /// What was written, or why not.
    pub message: String,
}

messages!(
    TfMessage,
    PoseStamped,
    TransformStamped,
    Odometry,
    OccupancyGrid,
    DiagnosticArray,
    GetDistancesRequest,
    GetDistancesResponse,
    GetEsdfBoxRequest,
    GetEsdfBoxResponse,
    SaveMapRequest,
    SaveMapResponse
);

/// A pose or sensor message, converted to the crate's types.
pub(crate) fn tf_message(m: TfMessage) -> Result<msg::Message, String> {
    Ok(msg::Message::Tf(m.transforms.into_iter().map(TransformStamped::stamped).collect::<Result<_, _>>()?))
}

/// `nav_msgs/Odometry` → the pose of its child frame.
pub(crate) fn odometry(m: Odometry) -> Result<msg::Message, String> {
    let transform = m.pose.pose.isometry()?;
    Ok(msg::Message::Odometry(msg::StampedTransform { header: m.header, child_frame: m.child_frame_id, transform }))
}

/// `geometry_msgs/PoseStamped` → its pose.
pub(crate) fn pose_stamped(m: PoseStamped) -> Result<msg::Message, String> {
    let transform = m.pose.isometry()?;
    Ok(msg::Message::PoseStamped(msg::StampedTransform { header: m.header, child_frame: String::new(), transform }))
}

/// `geometry_msgs/TransformStamped` → its transform.
pub(crate) fn transform_stamped(m: TransformStamped) -> Result<msg::Message, String> {
    Ok(msg::Message::TransformStamped(m.stamped()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use byteorder::LittleEndian;
    use edtmap_ros::msg::{Message, RegionOfInterest};
    use edtmap_ros::Encoding;
    use ros2_client::dds::rustdds::cdr_encoding;
    use std::fmt::Debug;
    use std::path::{Path, PathBuf};

    /// The bytes RustDDS's CDR encoder makes of `value` are the bytes the
    /// recordings' own CDR writer makes of `message` (after its 4-byte
    /// encapsulation header), and each side decodes the other's.
    fn codecs_agree<T: Serialize + DeserializeOwned + PartialEq + Debug>(value: &T, message: Message) {
        let name = message.type_name();
        let recorded = message.encode(Encoding::Cdr);
        let body = &recorded[4..];
        let dds = cdr_encoding::to_vec::<T, LittleEndian>(value).expect("serializes");
        assert_eq!(body, &dds[..], "{name}: the two encoders differ");
        let (back, _) = cdr_encoding::from_bytes::<T, LittleEndian>(body).expect("deserializes");
        assert_eq!(&back, value, "{name}: DDS decoding of the recording's bytes");
        assert_eq!(Message::decode(name, &recorded, Encoding::Cdr), Ok(message), "{name}: recording's decoding");
    }

    #[test]
    fn live_and_recorded_sensor_messages_are_the_same_bytes() {
        let header = |frame: &str| Header { stamp_ns: 1_700_000_000_123_456_789, frame_id: frame.into() };
        let cloud = PointCloud2::from_points(header("lidar"), &[[1.0, 2.0, 3.0], [-1.0, 0.5, f32::NAN]]);
        codecs_agree(&cloud, Message::PointCloud2(cloud.clone()));
        let image = Image {
            header: header("cam"),
            height: 2,
            width: 3,
            encoding: "16UC1".into(),
            is_bigendian: false,
            step: 6,
            data: vec![0xe8, 3, 0, 0, 0xd0, 7, 1, 0, 2, 0, 3, 0],
        };
        codecs_agree(&image, Message::Image(image.clone()));
        let k = [525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0];
        let info = CameraInfo {
            d: vec![0.1, -0.2, 0.0, 0.0, 0.05],
            binning_y: 2,
            roi: RegionOfInterest { x_offset: 3, y_offset: 4, height: 100, width: 200, do_rectify: true },
            ..CameraInfo::pinhole(header("cam"), 640, 480, k)
        };
        codecs_agree(&info, Message::CameraInfo(info.clone()));
        let scan = LaserScanMsg {
            header: header("laser"),
            angle_min: -1.5,
            angle_max: 1.5,
            angle_increment: 1.5,
            time_increment: 1e-4,
            scan_time: 0.1,
            range_min: 0.1,
            range_max: 30.0,
            ranges: vec![1.0, f32::INFINITY, 2.5],
            intensities: vec![10.0, 0.0, 7.0],
        };
        codecs_agree(&scan, Message::LaserScan(scan.clone()));
    }

    /// Keywords of C (C23), C++ (C++23, with alternative tokens) and Python
    /// (3.12, soft keywords included): a field named one of them breaks a
    /// ROS 2 code generator (`rosidl_generator_c` rejects `bool signed`).
    const KEYWORDS: &[&str] = &[
        // C
        "alignas",
        "alignof",
        "auto",
        "bool",
        "break",
        "case",
        "char",
        "const",
        "constexpr",
        "continue",
        "default",
        "do",
        "double",
        "else",
        "enum",
        "extern",
        "false",
        "float",
        "for",
        "goto",
        "if",
        "inline",
        "int",
        "long",
        "nullptr",
        "register",
        "restrict",
        "return",
        "short",
        "signed",
        "sizeof",
        "static",
        "static_assert",
        "struct",
        "switch",
        "thread_local",
        "true",
        "typedef",
        "typeof",
        "typeof_unqual",
        "union",
        "unsigned",
        "void",
        "volatile",
        "while",
        "_Alignas",
        "_Alignof",
        "_Atomic",
        "_BitInt",
        "_Bool",
        "_Complex",
        "_Decimal128",
        "_Decimal32",
        "_Decimal64",
        "_Generic",
        "_Imaginary",
        "_Noreturn",
        "_Static_assert",
        "_Thread_local",
        // C++
        "and",
        "and_eq",
        "asm",
        "bitand",
        "bitor",
        "catch",
        "char16_t",
        "char32_t",
        "char8_t",
        "class",
        "co_await",
        "co_return",
        "co_yield",
        "compl",
        "concept",
        "consteval",
        "constinit",
        "const_cast",
        "decltype",
        "delete",
        "dynamic_cast",
        "explicit",
        "export",
        "friend",
        "mutable",
        "namespace",
        "new",
        "noexcept",
        "not",
        "not_eq",
        "operator",
        "or",
        "or_eq",
        "private",
        "protected",
        "public",
        "reinterpret_cast",
        "requires",
        "static_cast",
        "template",
        "this",
        "throw",
        "try",
        "typeid",
        "typename",
        "using",
        "virtual",
        "wchar_t",
        "xor",
        "xor_eq",
        // Python
        "False",
        "None",
        "True",
        "as",
        "assert",
        "async",
        "await",
        "def",
        "del",
        "elif",
        "except",
        "finally",
        "from",
        "global",
        "import",
        "in",
        "is",
        "lambda",
        "nonlocal",
        "pass",
        "raise",
        "with",
        "yield",
        "match",
        "type",
        "_",
    ];

    fn interface_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("ros/ is readable").flatten() {
            let path = entry.path();
            if path.is_dir() {
                interface_files(&path, out);
            } else if matches!(path.extension().and_then(|e| e.to_str()), Some("msg" | "srv" | "action")) {
                out.push(path);
            }
        }
    }

    /// The field and constant names of a `.msg`/`.srv`/`.action` file:
    /// the second word of each line that is not a comment or separator.
    fn field_names(text: &str) -> Vec<String> {
        text.lines()
            .map(|l| l.split('#').next().unwrap_or("").trim())
            .filter(|l| !l.is_empty() && *l != "---")
            .filter_map(|l| l.split_whitespace().nth(1).map(|n| n.split('=').next().unwrap_or(n).to_string()))
            .collect()
    }

    #[test]
    fn no_interface_field_is_a_c_cpp_or_python_keyword() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../ros");
        let mut files = Vec::new();
        interface_files(&root, &mut files);
        assert!(files.len() >= 3, "interface files under {}: {files:?}", root.display());
        let mut bad = Vec::new();
        for f in &files {
            let text = std::fs::read_to_string(f).expect("readable");
            let names = field_names(&text);
            assert!(!names.is_empty(), "{} has no fields", f.display());
            bad.extend(
                names.into_iter().filter(|n| KEYWORDS.contains(&n.as_str())).map(|n| format!("{}: {n}", f.display())),
            );
        }
        assert!(bad.is_empty(), "fields named like keywords: {bad:?}");
    }

    #[test]
    fn field_names_are_read_as_the_generators_read_them() {
        let names =
            field_names("# c\nuint8 STATE_FREE=2   # x\ngeometry_msgs/Point[] points\n---\nbool signed\nuint8 A = 1\n");
        assert_eq!(names, ["STATE_FREE", "points", "signed", "A"]);
    }
}
