//! Poses `T_world_sensor` and their validation.

use crate::CoreError;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

/// Largest accepted deviation of a rotation from orthonormality.
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// Checks that a pose is finite and its rotation a unit quaternion.
pub fn check_pose(t: &Isometry3<f64>) -> Result<(), CoreError> {
    let q = t.rotation.quaternion();
    let finite = t.translation.vector.iter().chain(q.coords.iter()).all(|v| v.is_finite());
    if !finite {
        return Err(CoreError::BadPose(format!("not finite: translation {:?}, rotation {:?}", t.translation.vector.as_slice(), q.coords.as_slice())));
    }
    let norm = q.norm();
    if (norm - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(CoreError::BadPose(format!("rotation quaternion has norm {norm}, not 1")));
    }
    Ok(())
}

/// A pose from a row-major 4×4 homogeneous matrix, checked to be a rigid
/// transform (orthonormal rotation with determinant +1, last row `0 0 0 1`).
pub fn pose_from_matrix(m: &[[f64; 4]; 4]) -> Result<Isometry3<f64>, CoreError> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(CoreError::BadPose(format!("matrix has a non-finite entry: {m:?}")));
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(CoreError::BadPose(format!("last row is {:?}, not [0, 0, 0, 1]", m[3])));
    }
    let r = Matrix3::from_fn(|i, j| m[i][j]);
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    if err > ROTATION_TOLERANCE || r.determinant() < 0.0 {
        return Err(CoreError::BadPose(format!("rotation is not orthonormal (|RᵀR − I| = {err:.2e}, det = {:.4})", r.determinant())));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Isometry3::from_parts(Translation3::new(m[0][3], m[1][3], m[2][3]), rotation))
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
        m[0][0] = -1.0;
        assert!(pose_from_matrix(&m).expect_err("reflection").to_string().contains("det"));
    }
}
