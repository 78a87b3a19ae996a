//! Solid primitives with exact ray and box intersection, for ground truth.
//!
//! Every primitive is a closed convex solid, so the points of a ray that lie
//! in it form one closed interval of the ray parameter. Each primitive
//! computes that interval in closed form (slabs and quadratics); a ray's hit
//! is the interval's entry. Box tests compare the closest points of the two
//! solids, so they are exact up to floating-point rounding.

mod aabb;
mod ground;
mod round;
#[cfg(test)]
mod tests;

pub use aabb::Aabb;
pub use ground::Ground;
pub use round::{Cylinder, Sphere};

/// Any solid of a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Primitive {
    /// An axis-aligned box.
    Box(Aabb),
    /// A vertical capped cylinder.
    Cylinder(Cylinder),
    /// A ball.
    Sphere(Sphere),
    /// The half-space below a horizontal plane.
    Ground(Ground),
}

impl Primitive {
    /// Distance along the unit ray `origin + t·dir` at which it enters the
    /// solid, for `t` in `(0, t_max]`. A ray that starts inside the solid
    /// gives the distance at which it leaves it (if within `t_max`).
    #[inline]
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3], t_max: f64) -> Option<f64> {
        first_hit(self.span(origin, dir), t_max)
    }

    /// The closed interval of ray parameters inside the solid.
    #[inline]
    pub(crate) fn span(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<(f64, f64)> {
        match self {
            Primitive::Box(b) => b.span(origin, dir),
            Primitive::Cylinder(c) => c.span(origin, dir),
            Primitive::Sphere(s) => s.span(origin, dir),
            Primitive::Ground(g) => g.span(origin, dir),
        }
    }

    /// Whether the closed solid meets the closed box `[lo, hi]` (metres).
    #[inline]
    pub fn intersects_box(&self, lo: [f64; 3], hi: [f64; 3]) -> bool {
        match self {
            Primitive::Box(b) => b.intersects_box(lo, hi),
            Primitive::Cylinder(c) => c.intersects_box(lo, hi),
            Primitive::Sphere(s) => s.intersects_box(lo, hi),
            Primitive::Ground(g) => g.intersects_box(lo, hi),
        }
    }

    /// Whether point `p` lies in the closed solid.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        self.distance(p) == 0.0
    }

    /// Euclidean distance from `p` to the solid, metres (0 inside).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        match self {
            Primitive::Box(b) => b.distance(p),
            Primitive::Cylinder(c) => c.distance(p),
            Primitive::Sphere(s) => s.distance(p),
            Primitive::Ground(g) => g.distance(p),
        }
    }

    /// A box holding the solid (infinite sides for the ground).
    pub fn bounds(&self) -> Aabb {
        match self {
            Primitive::Box(b) => b.bounds(),
            Primitive::Cylinder(c) => c.bounds(),
            Primitive::Sphere(s) => s.bounds(),
            Primitive::Ground(g) => g.bounds(),
        }
    }

    /// The same solid moved by `shift` metres.
    pub fn translated(&self, shift: [f64; 3]) -> Primitive {
        match self {
            Primitive::Box(b) => Primitive::Box(b.translated(shift)),
            Primitive::Cylinder(c) => Primitive::Cylinder(c.translated(shift)),
            Primitive::Sphere(s) => Primitive::Sphere(s.translated(shift)),
            Primitive::Ground(g) => Primitive::Ground(g.translated(shift)),
        }
    }
}

impl From<Aabb> for Primitive {
    fn from(b: Aabb) -> Self {
        Primitive::Box(b)
    }
}

impl From<Cylinder> for Primitive {
    fn from(c: Cylinder) -> Self {
        Primitive::Cylinder(c)
    }
}

impl From<Sphere> for Primitive {
    fn from(s: Sphere) -> Self {
        Primitive::Sphere(s)
    }
}

impl From<Ground> for Primitive {
    fn from(g: Ground) -> Self {
        Primitive::Ground(g)
    }
}

/// The entry of a span into `(0, t_max]`; the exit when the ray starts
/// inside.
#[inline]
pub(crate) fn first_hit(span: Option<(f64, f64)>, t_max: f64) -> Option<f64> {
    let (t0, t1) = span?;
    let t = if t0 > 0.0 { t0 } else { t1 };
    (t > 0.0 && t <= t_max).then_some(t)
}

/// Ray parameters for which `o + t·d` lies in `[lo, hi]` along one axis.
#[inline]
pub(crate) fn slab(o: f64, d: f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    if d == 0.0 {
        // Parallel to the slab: everywhere or nowhere (avoids 0·∞).
        return (lo <= o && o <= hi).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let (a, b) = ((lo - o) / d, (hi - o) / d);
    Some((a.min(b), a.max(b)))
}

/// The intersection of two intervals, if not empty.
#[inline]
pub(crate) fn overlap(a: Option<(f64, f64)>, b: Option<(f64, f64)>) -> Option<(f64, f64)> {
    let ((a0, a1), (b0, b1)) = (a?, b?);
    let (lo, hi) = (a0.max(b0), a1.min(b1));
    (lo <= hi).then_some((lo, hi))
}

/// Roots interval of `a t² + 2 b t + c ≤ 0` for `a > 0`, computed without
/// cancellation.
#[inline]
pub(crate) fn quadratic_span(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let q = -(b + b.signum() * disc.sqrt());
    if q == 0.0 {
        return Some((0.0, 0.0));
    }
    let (r0, r1) = (q / a, c / q);
    Some((r0.min(r1), r0.max(r1)))
}

/// How far `v` lies outside `[lo, hi]` (0 inside).
#[inline]
pub(crate) fn gap(v: f64, lo: f64, hi: f64) -> f64 {
    (lo - v).max(v - hi).max(0.0)
}
