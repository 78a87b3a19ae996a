//! The CPU's wavefront integration (paper §IV-C, Algorithms 2 and 3) over
//! a lazily loaded working region ([`lazy`]); the exact mode's host side
//! is `edtmap_core::exact`, shared with every backend.

pub mod lazy;
pub mod separable;
pub mod wavefront;
