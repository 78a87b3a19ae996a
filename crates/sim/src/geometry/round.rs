//! Round solids: vertical cylinders and spheres.

use super::{gap, overlap, quadratic_span, slab, Aabb};

/// A vertical cylinder with flat caps: the points within `radius_m` of the
/// axis through `centre_xy` with `z_min ≤ z ≤ z_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    /// Axis position (x, y), metres.
    pub centre_xy: [f64; 2],
    /// Radius, metres.
    pub radius_m: f64,
    /// Bottom cap height, metres.
    pub z_min: f64,
    /// Top cap height, metres.
    pub z_max: f64,
}

/// A ball: the points within `radius_m` of `centre`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre, metres.
    pub centre: [f64; 3],
    /// Radius, metres.
    pub radius_m: f64,
}

impl Cylinder {
    /// See [`super::Primitive::ray_hit`].
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3], t_max: f64) -> Option<f64> {
        super::first_hit(self.span(origin, dir), t_max)
    }

    #[inline]
    pub(crate) fn span(&self, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
        let (ox, oy) = (o[0] - self.centre_xy[0], o[1] - self.centre_xy[1]);
        let a = d[0] * d[0] + d[1] * d[1];
        let c = ox * ox + oy * oy - self.radius_m * self.radius_m;
        let disk = if a == 0.0 {
            // A vertical ray: inside the disk for every t or for none.
            (c <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY))
        } else {
            quadratic_span(a, ox * d[0] + oy * d[1], c)
        };
        overlap(disk, slab(o[2], d[2], self.z_min, self.z_max))
    }

    /// Whether the closed cylinder meets the closed box `[lo, hi]`: the
    /// solid is a disk times an interval, so both projections must meet.
    #[inline]
    pub fn intersects_box(&self, lo: [f64; 3], hi: [f64; 3]) -> bool {
        let dx = gap(self.centre_xy[0], lo[0], hi[0]);
        let dy = gap(self.centre_xy[1], lo[1], hi[1]);
        lo[2] <= self.z_max && hi[2] >= self.z_min && dx * dx + dy * dy <= self.radius_m * self.radius_m
    }

    /// Distance from `p` to the cylinder, metres (0 inside).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        let r = (p[0] - self.centre_xy[0]).hypot(p[1] - self.centre_xy[1]);
        let radial = (r - self.radius_m).max(0.0);
        radial.hypot(gap(p[2], self.z_min, self.z_max))
    }

    /// The box holding the cylinder.
    pub fn bounds(&self) -> Aabb {
        let [x, y] = self.centre_xy;
        let r = self.radius_m;
        Aabb { min: [x - r, y - r, self.z_min], max: [x + r, y + r, self.z_max] }
    }

    /// The cylinder moved by `shift` metres.
    pub fn translated(&self, shift: [f64; 3]) -> Cylinder {
        let [x, y] = self.centre_xy;
        Cylinder {
            centre_xy: [x + shift[0], y + shift[1]],
            z_min: self.z_min + shift[2],
            z_max: self.z_max + shift[2],
            ..*self
        }
    }
}

impl Sphere {
    /// See [`super::Primitive::ray_hit`].
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3], t_max: f64) -> Option<f64> {
        super::first_hit(self.span(origin, dir), t_max)
    }

    #[inline]
    pub(crate) fn span(&self, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
        let rel = [0, 1, 2].map(|i| o[i] - self.centre[i]);
        let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let b = rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2];
        let c = rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2] - self.radius_m * self.radius_m;
        if a == 0.0 {
            return None;
        }
        quadratic_span(a, b, c)
    }

    /// Whether the closed ball meets the closed box `[lo, hi]`.
    #[inline]
    pub fn intersects_box(&self, lo: [f64; 3], hi: [f64; 3]) -> bool {
        let g = [0, 1, 2].map(|i| gap(self.centre[i], lo[i], hi[i]));
        g[0] * g[0] + g[1] * g[1] + g[2] * g[2] <= self.radius_m * self.radius_m
    }

    /// Distance from `p` to the ball, metres (0 inside).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        let d = [0, 1, 2].map(|i| p[i] - self.centre[i]);
        ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - self.radius_m).max(0.0)
    }

    /// The box holding the ball.
    pub fn bounds(&self) -> Aabb {
        let r = self.radius_m;
        Aabb { min: self.centre.map(|c| c - r), max: self.centre.map(|c| c + r) }
    }

    /// The ball moved by `shift` metres.
    pub fn translated(&self, shift: [f64; 3]) -> Sphere {
        Sphere { centre: [0, 1, 2].map(|i| self.centre[i] + shift[i]), ..*self }
    }
}
