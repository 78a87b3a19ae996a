//! Poses `T_world_sensor`, their validation, and the one rule every front
//! end (dataset folders, trajectories, ROS messages, Python, the C API)
//! applies to the rotations it reads.
//!
//! Published ground truth is rarely orthonormal to machine precision: the
//! rotations of common RGB-D datasets (7-Scenes, for one) are orthonormal
//! only to 1e-4 to 4e-4 (|RᵀR − I|), and a pose file printed with four
//! decimals or a quaternion with three is no better. A rotation is therefore
//! accepted while it is within [`ROTATION_TOLERANCE`] of one and replaced by
//! the nearest rotation; beyond it the numbers are not a rotation (a typo, a
//! scaled or sheared matrix, a reflection) and are refused.

use crate::CoreError;
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};

/// Largest accepted deviation of a rotation read from numbers: |RᵀR − I|
/// (largest entry) for a matrix, |‖q‖ − 1| for a quaternion.
pub const ROTATION_TOLERANCE: f64 = 1e-2;

/// Deviations up to this are rounding in the numbers' last printed digits
/// and pass without a note; larger ones (still within
/// [`ROTATION_TOLERANCE`]) are counted by [`PoseAdjustments`] so that the
/// reader of a recording can say once how far its poses were off.
pub const ROTATION_NOTED: f64 = 1e-4;

/// Checks that a pose is finite and its rotation a unit quaternion.
pub fn check_pose(t: &Isometry3<f64>) -> Result<(), CoreError> {
    let q = t.rotation.quaternion();
    let finite = t.translation.vector.iter().chain(q.coords.iter()).all(|v| v.is_finite());
    if !finite {
        return Err(CoreError::BadPose(format!(
            "not finite: translation {:?}, rotation {:?}",
            t.translation.vector.as_slice(),
            q.coords.as_slice()
        )));
    }
    let norm = q.norm();
    if (norm - 1.0).abs() > ROTATION_NOTED {
        return Err(CoreError::BadPose(format!("rotation quaternion has norm {norm}, not 1")));
    }
    Ok(())
}

/// The rotation of a 3 × 3 matrix and its deviation |RᵀR − I| (largest
/// entry). Within [`ROTATION_NOTED`] the matrix's own quaternion is taken (normalised);
/// up to [`ROTATION_TOLERANCE`] the matrix is first projected onto the
/// nearest rotation (the orthogonal polar factor, `U Vᵀ` of its SVD);
/// beyond it, or with a negative determinant, it is refused.
pub fn rotation_from_matrix(r: &Matrix3<f64>) -> Result<(UnitQuaternion<f64>, f64), CoreError> {
    if r.iter().any(|v| !v.is_finite()) {
        return Err(CoreError::BadPose(format!("rotation has a non-finite entry: {:?}", r.transpose().as_slice())));
    }
    let deviation = (r.transpose() * r - Matrix3::identity()).abs().max();
    let det = r.determinant();
    if deviation > ROTATION_TOLERANCE || det <= 0.0 {
        return Err(CoreError::BadPose(format!(
            "rotation is not orthonormal (|RᵀR − I| = {deviation:.2e}, det = {det:.4}; accepted up to {ROTATION_TOLERANCE:.0e} and det > 0): \
             write the pose's rotation with more digits, or re-orthonormalise it"
        )));
    }
    let rotation = if deviation <= ROTATION_NOTED { Rotation3::from_matrix_unchecked(*r) } else { nearest_rotation(r) };
    // The matrix's quaternion has a norm off by about the deviation:
    // normalised, it is a unit quaternion to the last bit, and a reader
    // given it back (Python, a recording) keeps it bit for bit.
    Ok((UnitQuaternion::from_quaternion(*UnitQuaternion::from_rotation_matrix(&rotation).quaternion()), deviation))
}

/// The rotation nearest to `r` in the Frobenius norm: `U Vᵀ` of its SVD,
/// for a matrix with a positive determinant.
fn nearest_rotation(r: &Matrix3<f64>) -> Rotation3<f64> {
    let svd = r.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => Rotation3::from_matrix_unchecked(u * v_t),
        // nalgebra computes both factors when asked; keep the matrix's own
        // quaternion should it ever not.
        _ => Rotation3::from_matrix_unchecked(*r),
    }
}

/// The rotation of a quaternion and its deviation |‖q‖ − 1|: normalised
/// (a quaternion already of unit norm to 1e-12 is kept bit for bit) while
/// the deviation is within [`ROTATION_TOLERANCE`], refused beyond it.
pub fn rotation_from_quaternion(q: Quaternion<f64>) -> Result<(UnitQuaternion<f64>, f64), CoreError> {
    let norm = q.norm();
    let deviation = (norm - 1.0).abs();
    if !deviation.is_finite() || deviation > ROTATION_TOLERANCE {
        let [x, y, z, w] = [q.i, q.j, q.k, q.w];
        return Err(CoreError::BadPose(format!(
            "quaternion (x {x}, y {y}, z {z}, w {w}) has norm {norm}, not 1 (accepted within {ROTATION_TOLERANCE:.0e} and normalised)"
        )));
    }
    let rotation =
        if deviation < 1e-12 { UnitQuaternion::new_unchecked(q) } else { UnitQuaternion::from_quaternion(q) };
    Ok((rotation, deviation))
}

/// A pose from a row-major 4×4 homogeneous matrix, checked to be a rigid
/// transform (last row `0 0 0 1`, rotation as [`rotation_from_matrix`]
/// accepts it).
pub fn pose_from_matrix(m: &[[f64; 4]; 4]) -> Result<Isometry3<f64>, CoreError> {
    pose_from_matrix_noted(m, None)
}

/// [`pose_from_matrix`], counting an adjusted rotation in `noted`.
pub fn pose_from_matrix_noted(m: &[[f64; 4]; 4], noted: Option<&PoseAdjustments>) -> Result<Isometry3<f64>, CoreError> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(CoreError::BadPose(format!("matrix has a non-finite entry: {m:?}")));
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(CoreError::BadPose(format!("last row is {:?}, not [0, 0, 0, 1]", m[3])));
    }
    let (rotation, deviation) = rotation_from_matrix(&Matrix3::from_fn(|i, j| m[i][j]))?;
    if let Some(noted) = noted {
        noted.note(deviation);
    }
    Ok(Isometry3::from_parts(Translation3::new(m[0][3], m[1][3], m[2][3]), rotation))
}

/// A tally of the rotations a reader adjusted (deviation above
/// [`ROTATION_NOTED`]), shared by the threads that read one recording, so
/// that it can warn once with the worst deviation rather than per frame.
#[derive(Debug, Default)]
pub struct PoseAdjustments {
    count: AtomicUsize,
    /// The worst deviation's bits: non-negative `f64`s order as their bits.
    worst_bits: AtomicU64,
}

impl PoseAdjustments {
    /// Counts `deviation` if it is above [`ROTATION_NOTED`].
    pub fn note(&self, deviation: f64) {
        if deviation > ROTATION_NOTED {
            self.count.fetch_add(1, Relaxed);
            self.worst_bits.fetch_max(deviation.to_bits(), Relaxed);
        }
    }

    /// How many rotations were adjusted.
    pub fn count(&self) -> usize {
        self.count.load(Relaxed)
    }

    /// The largest deviation noted (0 when none).
    pub fn worst(&self) -> f64 {
        f64::from_bits(self.worst_bits.load(Relaxed))
    }

    /// The one warning for a recording named `what`, if any rotation was
    /// adjusted.
    pub fn warning(&self, what: &str) -> Option<String> {
        let n = self.count();
        (n > 0).then(|| {
            format!(
                "{what}: {n} pose{} had rotations orthonormal only to {:.2e} (worst |RᵀR − I| or |‖q‖ − 1|); \
                 each was replaced by the nearest rotation (accepted up to {ROTATION_TOLERANCE:.0e})",
                if n == 1 { "" } else { "s" },
                self.worst()
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Quaternion, Vector3};

    #[test]
    fn matrix_round_trip() {
        let t = Isometry3::new(Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.1, 0.2, -0.3));
        let h = t.to_homogeneous();
        let m = [0, 1, 2, 3].map(|i| [0, 1, 2, 3].map(|j| h[(i, j)]));
        let back = pose_from_matrix(&m).expect("rigid");
        assert!((back.to_homogeneous() - h).abs().max() < 1e-12);
    }

    #[test]
    fn non_unit_and_nan_rotations_are_rejected() {
        let q = UnitQuaternion::new_unchecked(Quaternion::new(2.0, 0.0, 0.0, 0.0));
        let t = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.0), q);
        assert!(check_pose(&t).expect_err("norm 2").to_string().contains("norm"));
        let t = Isometry3::translation(f64::NAN, 0.0, 0.0);
        assert!(check_pose(&t).is_err());
        let mut m = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        m[0][0] = 2.0;
        assert!(pose_from_matrix(&m).is_err());
        m[0][0] = 1.02;
        assert!(pose_from_matrix(&m).expect_err("2 % scale").to_string().contains("accepted up to"));
        m[0][0] = -1.0;
        assert!(pose_from_matrix(&m).expect_err("reflection").to_string().contains("det"));
    }

    /// A rotation about an axis written as published ground truth is: every
    /// entry perturbed in its fourth decimal.
    fn published(angle: f64, noise: f64) -> Matrix3<f64> {
        let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8)), angle)
            .into_inner();
        r + Matrix3::from_fn(|i, j| noise * (((3 * i + j) as f64 * 1.7).sin()))
    }

    #[test]
    fn published_rotations_are_projected_onto_the_nearest_rotation() {
        let noisy = published(0.7, 2e-4);
        let (q, deviation) = rotation_from_matrix(&noisy).expect("within the tolerance");
        assert!(deviation > ROTATION_NOTED && deviation < ROTATION_TOLERANCE, "{deviation}");
        let r = q.to_rotation_matrix().into_inner();
        // The nearest rotation: orthonormal, and no rotation is closer. The
        // polar factor minimises ‖R − M‖ over rotations; check it against
        // rotations perturbed about every axis.
        assert!((r.transpose() * r - Matrix3::identity()).abs().max() < 1e-12);
        let d0 = (r - noisy).norm();
        for axis in [Vector3::x(), Vector3::y(), Vector3::z(), Vector3::new(1.0, 1.0, 1.0).normalize()] {
            for step in [1e-5, -1e-5, 1e-4, -1e-4] {
                let other = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), step).into_inner() * r;
                assert!((other - noisy).norm() >= d0 - 1e-15, "{axis:?} {step}");
            }
        }
        let noted = PoseAdjustments::default();
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().enumerate().take(3) {
            for (j, v) in row.iter_mut().enumerate().take(3) {
                *v = noisy[(i, j)];
            }
        }
        m[3][3] = 1.0;
        pose_from_matrix_noted(&m, Some(&noted)).expect("accepted");
        let exact = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.2).into_inner();
        let mut e = m;
        for (i, row) in e.iter_mut().enumerate().take(3) {
            for (j, v) in row.iter_mut().enumerate().take(3) {
                *v = exact[(i, j)];
            }
        }
        pose_from_matrix_noted(&e, Some(&noted)).expect("exact");
        assert_eq!(noted.count(), 1);
        assert_eq!(noted.worst(), deviation);
        let warning = noted.warning("frames").expect("one adjusted");
        assert!(warning.contains("1 pose had") && warning.contains(&format!("{deviation:.2e}")), "{warning}");
    }

    #[test]
    fn quaternions_within_the_tolerance_are_normalised() {
        let q = Quaternion::new(0.707, 0.0, 0.0, 0.707);
        let (u, deviation) = rotation_from_quaternion(q).expect("three decimals");
        assert!((u.norm() - 1.0).abs() < 1e-15 && deviation > 1e-4);
        let unit = *UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3).quaternion();
        assert_eq!(rotation_from_quaternion(unit).expect("unit").0.quaternion(), &unit);
        assert!(rotation_from_quaternion(Quaternion::new(0.9, 0.0, 0.0, 0.0)).is_err());
        assert!(rotation_from_quaternion(Quaternion::new(f64::NAN, 0.0, 0.0, 0.0)).is_err());
    }
}
