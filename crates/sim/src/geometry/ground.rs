//! The ground: a half-space below a horizontal plane.

use super::{slab, Aabb};

/// The half-space `z ≤ height_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ground {
    /// Height of the surface, metres.
    pub height_m: f64,
}

impl Ground {
    /// See [`super::Primitive::ray_hit`].
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3], t_max: f64) -> Option<f64> {
        super::first_hit(self.span(origin, dir), t_max)
    }

    #[inline]
    pub(crate) fn span(&self, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
        slab(o[2], d[2], f64::NEG_INFINITY, self.height_m)
    }

    /// Whether the half-space meets the closed box `[lo, hi]`.
    #[inline]
    pub fn intersects_box(&self, lo: [f64; 3], _hi: [f64; 3]) -> bool {
        lo[2] <= self.height_m
    }

    /// Distance from `p` to the half-space, metres (0 inside).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        (p[2] - self.height_m).max(0.0)
    }

    /// Infinite in x, y and downwards.
    pub fn bounds(&self) -> Aabb {
        let inf = f64::INFINITY;
        Aabb { min: [-inf, -inf, -inf], max: [inf, inf, self.height_m] }
    }

    /// The ground moved by `shift` metres (only z matters).
    pub fn translated(&self, shift: [f64; 3]) -> Ground {
        Ground { height_m: self.height_m + shift[2] }
    }
}
