//! Pinhole depth camera: intrinsics and depth images.

use super::{check_range, RangeLimits, ReturnBatch, SensorModel, SensorRay, View, RETURN_BATCH};
use crate::CoreError;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A pinhole depth camera. Optical frame: x right, y down, z forward; pixel
/// `(u, v)` has its centre at `u`, `v` (the OpenCV convention). Depth is the
/// z coordinate of the surface point, not its range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PinholeCamera {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Valid depth range in metres.
    pub range: RangeLimits,
}

/// Depth values of an image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum DepthData {
    /// Depth in metres.
    Metres(Vec<f32>),
    /// Raw 16-bit depth: metres = value × `metres_per_unit`; 0 is no return.
    U16 {
        /// The raw values.
        values: Vec<u16>,
        /// Scale to metres (0.001 for millimetres).
        metres_per_unit: f32,
    },
}

/// A depth image: `width × height` depths, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The depths.
    pub data: DepthData,
}

impl DepthImage {
    /// Depth in metres of pixel index `i`, or NaN for no return.
    #[inline]
    pub fn depth_m(&self, i: usize) -> f32 {
        match &self.data {
            DepthData::Metres(d) => d[i],
            DepthData::U16 { values, metres_per_unit } => raw_depth_m(values[i], *metres_per_unit),
        }
    }

    /// Depths in metres of the pixels from index `start` on, as many as
    /// `out` holds ([`Self::depth_m`] of each).
    #[inline]
    pub fn depths_m(&self, start: usize, out: &mut [f32]) {
        let end = start + out.len();
        match &self.data {
            DepthData::Metres(d) => out.copy_from_slice(&d[start..end]),
            DepthData::U16 { values, metres_per_unit } => {
                for (o, &v) in out.iter_mut().zip(&values[start..end]) {
                    *o = raw_depth_m(v, *metres_per_unit);
                }
            }
        }
    }

    fn len(&self) -> usize {
        match &self.data {
            DepthData::Metres(d) => d.len(),
            DepthData::U16 { values, .. } => values.len(),
        }
    }
}

/// Depth in metres of a raw 16-bit value, or NaN for 0 (no return).
#[inline]
pub fn raw_depth_m(value: u16, metres_per_unit: f32) -> f32 {
    match value {
        0 => f32::NAN,
        v => v as f32 * metres_per_unit,
    }
}

/// Most pixels a depth image may have: 8192 × 8192.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 26;

impl PinholeCamera {
    /// Checks the intrinsics.
    pub fn validate(&self) -> Result<(), CoreError> {
        for (field, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CoreError::InvalidParam {
                    field,
                    value: v.to_string(),
                    reason: "focal length must be positive",
                });
            }
        }
        for (field, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(CoreError::InvalidParam { field, value: v.to_string(), reason: "must be finite" });
            }
        }
        if self.width == 0 || self.height == 0 {
            return Err(CoreError::InvalidParam {
                field: "width/height",
                value: format!("{}x{}", self.width, self.height),
                reason: "image must have pixels",
            });
        }
        if u64::from(self.width) * u64::from(self.height) > MAX_IMAGE_PIXELS {
            return Err(CoreError::InvalidParam {
                field: "width/height",
                value: format!("{}x{}", self.width, self.height),
                reason: "at most 2^26 pixels (8192 × 8192)",
            });
        }
        check_range(&self.range)
    }

    /// Checks that `image` has this camera's size and a valid scale.
    pub fn check(&self, image: &DepthImage) -> Result<(), CoreError> {
        if (image.width, image.height) != (self.width, self.height) {
            return Err(CoreError::BadMeasurement(format!(
                "depth image is {}x{}, the camera intrinsics say {}x{}",
                image.width, image.height, self.width, self.height
            )));
        }
        if image.len() != (image.width * image.height) as usize {
            return Err(CoreError::BadMeasurement(format!(
                "depth image {}x{} has {} values",
                image.width,
                image.height,
                image.len()
            )));
        }
        if let DepthData::U16 { metres_per_unit, .. } = image.data {
            if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
                return Err(CoreError::BadMeasurement(format!("depth scale {metres_per_unit} must be positive")));
            }
        }
        Ok(())
    }

    /// Unnormalised ray of pixel `(u, v)` with z = 1.
    #[inline]
    pub fn pixel_ray(&self, u: u32, v: u32) -> [f64; 3] {
        [(u as f64 - self.cx) / self.fx, (v as f64 - self.cy) / self.fy, 1.0]
    }

    /// Fills `batch` with the points of the pixels from index `start` on,
    /// one per entry of `xs` (their `(u − cx) / fx`), on a row at
    /// `y = (v − cy) / fy`: NaN where the depth is not a valid return.
    fn fill(&self, image: &DepthImage, start: usize, xs: &[f64], y: f64, batch: &mut ReturnBatch) {
        let mut depths = [f32::NAN; RETURN_BATCH];
        image.depths_m(start, &mut depths[..xs.len()]);
        let mut x = [0.0; RETURN_BATCH];
        x[..xs.len()].copy_from_slice(xs);
        batch.len = xs.len();
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.points_avx2(&depths, &x, y, batch) };
        }
        self.points(&depths, &x, y, batch);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn points_avx2(
        &self,
        depths: &[f32; RETURN_BATCH],
        x: &[f64; RETURN_BATCH],
        y: f64,
        batch: &mut ReturnBatch,
    ) {
        self.points(depths, x, y, batch)
    }

    /// A batch's points from its depths, without branches so that the
    /// compiler keeps them in vector registers.
    #[inline(always)]
    fn points(&self, depths: &[f32; RETURN_BATCH], x: &[f64; RETURN_BATCH], y: f64, batch: &mut ReturnBatch) {
        let [px, py, pz] = &mut batch.xyz;
        for i in 0..RETURN_BATCH {
            let d = if self.range.accepts(depths[i]) { depths[i] as f64 } else { f64::NAN };
            px[i] = x[i] * d;
            py[i] = y * d;
            pz[i] = d;
        }
    }

    /// Pixel index whose centre is nearest to the projection of `p`
    /// (optical frame), if in front of the camera and inside the image.
    #[inline]
    pub fn project(&self, p: [f32; 3]) -> Option<usize> {
        if p[2] <= 0.0 {
            return None;
        }
        let u = (self.fx as f32 * p[0] / p[2] + self.cx as f32 + 0.5).floor();
        let v = (self.fy as f32 * p[1] / p[2] + self.cy as f32 + 0.5).floor();
        if u < 0.0 || v < 0.0 || u >= self.width as f32 || v >= self.height as f32 {
            return None;
        }
        Some(u as usize + self.width as usize * v as usize)
    }
}

impl SensorModel for PinholeCamera {
    type Data = DepthImage;
    const NAME: &'static str = "depth";
    const KIND: &'static str = "depth camera";
    const PROJECTS: bool = true;

    fn validate(&self) -> Result<(), CoreError> {
        PinholeCamera::validate(self)
    }

    fn check(&self, image: &DepthImage) -> Result<(), CoreError> {
        PinholeCamera::check(self, image)
    }

    fn range(&self) -> RangeLimits {
        self.range
    }

    /// Calls `f` with the points of `image`'s pixels (camera frame,
    /// metres), a batch of up to [`RETURN_BATCH`] pixels of a row at a
    /// time: pixel `(u, v)` at depth `d` is `((u − cx) / fx · d,
    /// (v − cy) / fy · d, d)`, and NaN where its depth is not a valid
    /// return. Rows run in parallel; the order of the calls is
    /// unspecified.
    fn par_returns(&self, image: &DepthImage, _rays: &mut Vec<SensorRay>, f: impl Fn(&ReturnBatch) + Sync) {
        let xs: Vec<f64> = (0..self.width).map(|u| (u as f64 - self.cx) / self.fx).collect();
        let width = self.width as usize;
        (0..self.height).into_par_iter().with_min_len(8).for_each(|v| {
            let y = (v as f64 - self.cy) / self.fy;
            let row = width * v as usize;
            let mut batch = ReturnBatch::new();
            for (start, xs) in (0..width).step_by(RETURN_BATCH).zip(xs.chunks(RETURN_BATCH)) {
                self.fill(image, row + start, xs, y, &mut batch);
                f(&batch);
            }
        });
    }

    /// One ray per pixel.
    fn rays(&self, image: &DepthImage, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        for v in 0..self.height {
            for u in 0..self.width {
                let d = image.depth_m((u + self.width * v) as usize);
                let ray = self.pixel_ray(u, v);
                let norm = (ray[0] * ray[0] + ray[1] * ray[1] + 1.0).sqrt();
                let dir = ray.map(|c| (c / norm) as f32);
                let valid = d.is_finite() && d >= self.range.min_m && d <= self.range.max_m;
                if valid {
                    out.push(SensorRay { dir, range_m: d * norm as f32, hit: true });
                } else if clear_no_return {
                    out.push(SensorRay { dir, range_m: self.range.max_m * norm as f32, hit: false });
                }
            }
        }
    }

    fn view<'a>(&'a self, image: &'a DepthImage) -> Option<View<'a>> {
        Some(View::Pinhole { camera: self, image })
    }
}
