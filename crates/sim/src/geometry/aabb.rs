//! Axis-aligned boxes.

use super::{gap, overlap, slab};

/// An axis-aligned box `[min, max]`, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lowest corner.
    pub min: [f64; 3],
    /// Highest corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// The box spanning two corners, in any order.
    pub fn new(a: [f64; 3], b: [f64; 3]) -> Aabb {
        Aabb { min: [0, 1, 2].map(|i| a[i].min(b[i])), max: [0, 1, 2].map(|i| a[i].max(b[i])) }
    }

    /// The box of size `size` whose lowest corner is `min`.
    pub fn with_size(min: [f64; 3], size: [f64; 3]) -> Aabb {
        Aabb::new(min, [0, 1, 2].map(|i| min[i] + size[i]))
    }

    /// The smallest box holding both boxes.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: [0, 1, 2].map(|i| self.min[i].min(other.min[i])),
            max: [0, 1, 2].map(|i| self.max[i].max(other.max[i])),
        }
    }

    /// See [`super::Primitive::ray_hit`].
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3], t_max: f64) -> Option<f64> {
        super::first_hit(self.span(origin, dir), t_max)
    }

    #[inline]
    pub(crate) fn span(&self, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
        let x = slab(o[0], d[0], self.min[0], self.max[0]);
        let y = slab(o[1], d[1], self.min[1], self.max[1]);
        let z = slab(o[2], d[2], self.min[2], self.max[2]);
        overlap(overlap(x, y), z)
    }

    /// Whether the closed box meets the closed box `[lo, hi]`.
    #[inline]
    pub fn intersects_box(&self, lo: [f64; 3], hi: [f64; 3]) -> bool {
        (0..3).all(|i| lo[i] <= self.max[i] && hi[i] >= self.min[i])
    }

    /// Distance from `p` to the box, metres (0 inside).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        let g = [0, 1, 2].map(|i| gap(p[i], self.min[i], self.max[i]));
        (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt()
    }

    /// The box itself.
    pub fn bounds(&self) -> Aabb {
        *self
    }

    /// The box moved by `shift` metres.
    pub fn translated(&self, shift: [f64; 3]) -> Aabb {
        Aabb { min: [0, 1, 2].map(|i| self.min[i] + shift[i]), max: [0, 1, 2].map(|i| self.max[i] + shift[i]) }
    }
}
