//! Message decoding against hand-laid-out bytes of both wire formats, and
//! round trips of every type.

use super::msg::*;
use super::Encoding;
use edtmap_core::sensor::DepthData;
use nalgebra::{Isometry3, Vector3};

fn header(stamp_ns: i64, frame: &str) -> Header {
    Header { stamp_ns, frame_id: frame.into() }
}

fn transform(child: &str) -> StampedTransform {
    StampedTransform {
        header: header(1_000_000_002, "map"),
        child_frame: child.into(),
        transform: Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.0, 0.0, 0.5)),
    }
}

fn le(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn cdr_transform_stamped_matches_the_published_layout() {
    let t = transform("b");
    let q = t.transform.rotation.quaternion();
    // Encapsulation, sec 1, nanosec 2, "map\0", "b\0", 2 bytes of padding
    // to align the float64s at 8 from the end of the encapsulation.
    let mut bytes =
        vec![0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 4, 0, 0, 0, b'm', b'a', b'p', 0, 2, 0, 0, 0, b'b', 0, 0, 0];
    bytes.extend(le(&[1.0, 2.0, 3.0, q.i, q.j, q.k, q.w]));
    assert_eq!(Message::TransformStamped(t.clone()).encode(Encoding::Cdr), bytes);
    assert_eq!(
        Message::decode("geometry_msgs/TransformStamped", &bytes, Encoding::Cdr),
        Ok(Message::TransformStamped(t.clone()))
    );
    // The same message in big-endian CDR.
    let mut be = vec![0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 4, b'm', b'a', b'p', 0, 0, 0, 0, 2, b'b', 0, 0, 0];
    be.extend([1.0, 2.0, 3.0, q.i, q.j, q.k, q.w].iter().flat_map(|v: &f64| v.to_be_bytes()));
    assert_eq!(Message::decode("geometry_msgs/TransformStamped", &be, Encoding::Cdr), Ok(Message::TransformStamped(t)));
}

#[test]
fn ros1_transform_stamped_matches_the_published_layout() {
    let t = transform("b");
    let q = t.transform.rotation.quaternion();
    // seq 0, secs 1, nsecs 2, "map", "b", no padding.
    let mut bytes = vec![0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'm', b'a', b'p', 1, 0, 0, 0, b'b'];
    bytes.extend(le(&[1.0, 2.0, 3.0, q.i, q.j, q.k, q.w]));
    assert_eq!(Message::TransformStamped(t.clone()).encode(Encoding::Ros1), bytes);
    assert_eq!(
        Message::decode("geometry_msgs/TransformStamped", &bytes, Encoding::Ros1),
        Ok(Message::TransformStamped(t))
    );
}

fn every_message() -> Vec<Message> {
    let cloud = PointCloud2::from_points(header(5, "lidar"), &[[1.0, 2.0, 3.0], [-1.0, 0.5, 9.0]]);
    let image = Image {
        header: header(6, "cam"),
        height: 2,
        width: 2,
        encoding: "16UC1".into(),
        is_bigendian: false,
        step: 4,
        data: vec![1, 0, 2, 0, 3, 0, 0, 0],
    };
    let k = [500.0, 0.0, 1.0, 0.0, 501.0, 1.0, 0.0, 0.0, 1.0];
    let info = CameraInfo {
        d: vec![0.1, 0.0, 0.0, 0.0, 0.0],
        binning_x: 2,
        roi: RegionOfInterest { x_offset: 1, y_offset: 2, height: 3, width: 4, do_rectify: true },
        ..CameraInfo::pinhole(header(6, "cam"), 2, 2, k)
    };
    let scan = LaserScanMsg {
        header: header(7, "laser"),
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 1.0,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0, 2.0, f32::INFINITY],
        intensities: vec![],
    };
    vec![
        Message::PointCloud2(cloud),
        Message::Image(image),
        Message::CameraInfo(info),
        Message::LaserScan(scan),
        Message::Odometry(transform("base_link")),
        Message::PoseStamped(StampedTransform { child_frame: String::new(), ..transform("") }),
        Message::TransformStamped(transform("base_link")),
        Message::Tf(vec![transform("odom"), transform("base_link")]),
    ]
}

#[test]
fn every_type_round_trips_in_both_encodings() {
    for encoding in [Encoding::Ros1, Encoding::Cdr] {
        for m in every_message() {
            let bytes = m.encode(encoding);
            assert_eq!(
                Message::decode(m.type_name(), &bytes, encoding).as_ref(),
                Ok(&m),
                "{} {encoding:?}",
                m.type_name()
            );
            // Every cut of the message is an error, never a panic;
            // odometry is read only up to the pose.
            let partial = matches!(m, Message::Odometry(_));
            for cut in 0..bytes.len() {
                let r = Message::decode(m.type_name(), &bytes[..cut], encoding);
                assert!(partial || r.is_err(), "{} cut at {cut}", m.type_name());
            }
        }
    }
}

#[test]
fn unknown_types_and_huge_lengths_are_refused() {
    let err = Message::decode("std_msgs/String", &[0, 0, 0, 0], Encoding::Ros1).expect_err("unknown type");
    assert!(err.contains("std_msgs/String"), "{err}");
    // A ranges array claiming 2^32 − 1 floats in a 60-byte message.
    let mut bytes = Message::LaserScan(LaserScanMsg::default()).encode(Encoding::Ros1);
    let at = bytes.len() - 8;
    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let err = Message::decode("sensor_msgs/LaserScan", &bytes, Encoding::Ros1).expect_err("huge");
    assert!(err.contains("ranges") && err.contains("exceeds"), "{err}");
}

#[test]
fn cloud_fields_of_any_type_and_byte_order() {
    // Points of 20 bytes: intensity f32 at 0, x f64 at 4, y i16 at 12, z f32 at 14, 2 bytes of padding.
    let fields = vec![
        PointField { name: "intensity".into(), offset: 0, datatype: 7, count: 1 },
        PointField { name: "x".into(), offset: 4, datatype: 8, count: 1 },
        PointField { name: "y".into(), offset: 12, datatype: 3, count: 1 },
        PointField { name: "z".into(), offset: 14, datatype: 7, count: 1 },
    ];
    let point = |x: f64, y: i16, z: f32, be: bool| -> Vec<u8> {
        let mut p = Vec::new();
        if be {
            p.extend(9f32.to_be_bytes());
            p.extend(x.to_be_bytes());
            p.extend(y.to_be_bytes());
            p.extend(z.to_be_bytes());
        } else {
            p.extend(9f32.to_le_bytes());
            p.extend(x.to_le_bytes());
            p.extend(y.to_le_bytes());
            p.extend(z.to_le_bytes());
        }
        p.extend([0, 0]);
        p
    };
    for be in [false, true] {
        // Two rows of one point each, rows padded to 24 bytes.
        let mut data = point(1.5, -2, 0.25, be);
        data.extend([0; 4]);
        data.extend(point(-3.0, 7, f32::NAN, be));
        let cloud = PointCloud2 {
            height: 2,
            width: 1,
            fields: fields.clone(),
            is_bigendian: be,
            point_step: 20,
            row_step: 24,
            data,
            ..Default::default()
        };
        let pts = cloud.xyz().expect("valid cloud").points;
        assert_eq!(pts[0], [1.5, -2.0, 0.25]);
        assert_eq!(pts[1][..2], [-3.0, 7.0]);
        assert!(pts[1][2].is_nan());
        let mut short = cloud.clone();
        short.data.truncate(30);
        assert!(short.xyz().expect_err("short").contains("needs 44 bytes"));
        let mut no_z = cloud.clone();
        no_z.fields.pop();
        assert!(no_z.xyz().expect_err("no z").contains("no field z"));
        let mut wide = cloud;
        wide.fields[3].offset = 18;
        assert!(wide.xyz().expect_err("outside").contains("exceeds point_step"));
    }
}

#[test]
fn depth_images_in_millimetres_and_metres() {
    let mm = Image {
        height: 1,
        width: 3,
        encoding: "16UC1".into(),
        step: 8,
        data: vec![0xe8, 0x03, 0, 0, 0x01, 0x02, 9, 9],
        is_bigendian: false,
        ..Default::default()
    };
    let d = mm.depth(0.001).expect("16UC1");
    assert_eq!(d.data, DepthData::U16 { values: vec![1000, 0, 0x0201], metres_per_unit: 0.001 });
    let be = Image { is_bigendian: true, data: vec![0x03, 0xe8, 0, 0, 0x02, 0x01, 9, 9], ..mm.clone() };
    assert_eq!(be.depth(0.001).expect("big-endian").data, d.data);
    let m: Vec<u8> = [2.5f32, 0.0, f32::INFINITY].iter().flat_map(|v| v.to_le_bytes()).collect();
    let metres = Image { encoding: "32FC1".into(), step: 12, data: m, ..mm.clone() };
    let DepthData::Metres(v) = metres.depth(0.001).expect("32FC1").data else { panic!("metres") };
    assert_eq!(v[0], 2.5);
    assert!(v[1].is_nan() && v[2].is_nan());
    assert!(Image { encoding: "rgb8".into(), ..mm.clone() }.depth(0.001).expect_err("rgb").contains("rgb8"));
    assert!(Image { step: 4, ..mm.clone() }.depth(0.001).expect_err("narrow").contains("step"));
    assert!(Image { height: 2, ..mm }.depth(0.001).expect_err("short").contains("needs 16 bytes"));
}

#[test]
fn mutated_messages_decode_or_fail_without_panicking() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(0x5eed_0006);
    for encoding in [Encoding::Ros1, Encoding::Cdr] {
        for m in every_message() {
            let clean = m.encode(encoding);
            for _ in 0..300 {
                let mut bytes = clean.clone();
                for _ in 0..rng.random_range(1..4) {
                    let at = rng.random_range(0..bytes.len());
                    match rng.random_range(0..4) {
                        0 => bytes[at] ^= 1 << rng.random_range(0..8),
                        1 => bytes[at] = 0xff,
                        2 => bytes.truncate(at),
                        _ => bytes.insert(at, rng.random()),
                    }
                    if bytes.is_empty() {
                        break;
                    }
                }
                // Decoding and converting either succeed or say why.
                if let Ok(decoded) = Message::decode(m.type_name(), &bytes, encoding) {
                    match decoded {
                        Message::PointCloud2(c) => drop(c.xyz()),
                        Message::Image(i) => drop(i.depth(0.001)),
                        Message::LaserScan(s) => drop(s.scan()),
                        _ => {}
                    }
                }
            }
        }
    }
}
