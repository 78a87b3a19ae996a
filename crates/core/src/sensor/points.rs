//! Any source of 3D points with no structure to project into: ray casting
//! only.

use super::{check_range, norm, PointCloud, RangeLimits, SensorModel, SensorRay, View};
use crate::CoreError;

/// A sensor known only by the range of its returns; its measurements are
/// point clouds, which every 3D sensor can also deliver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSensor(pub RangeLimits);

impl SensorModel for PointSensor {
    type Data = PointCloud;
    const NAME: &'static str = "points";
    const KIND: &'static str = "point cloud";
    const PROJECTS: bool = false;

    fn validate(&self) -> Result<(), CoreError> {
        check_range(&self.0)
    }

    fn check(&self, cloud: &PointCloud) -> Result<(), CoreError> {
        match cloud.points.is_empty() {
            true => Err(CoreError::BadMeasurement("point cloud is empty".into())),
            false => Ok(()),
        }
    }

    fn range(&self) -> RangeLimits {
        self.0
    }

    /// A ray to every finite, non-zero point; a point past the maximum
    /// range still shows free space up to it.
    fn rays(&self, cloud: &PointCloud, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        for p in &cloud.points {
            let d = norm(*p);
            if !d.is_finite() || d == 0.0 {
                continue;
            }
            let dir = p.map(|c| c / d);
            if self.0.accepts(d) {
                out.push(SensorRay { dir, range_m: d, hit: true });
            } else if clear_no_return && d > self.0.max_m {
                out.push(SensorRay { dir, range_m: self.0.max_m, hit: false });
            }
        }
    }

    fn view<'a>(&'a self, _cloud: &'a PointCloud) -> Option<View<'a>> {
        None
    }
}
