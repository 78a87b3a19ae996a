//! The pipeline's three stages (paper Fig. 1), each an object that owns
//! its buffers and runs its device work on a [`crate::Backend`]:
//! [`OccupancyStage`] (§IV-A), [`BatchEdtStage`] (§IV-B) and
//! [`IntegrationStage`] (§IV-C), with [`exact`], the exact integration's
//! host side that every backend's [`crate::Backend::integrate`] shares.

mod batch;
pub mod exact;
mod integration;
mod occupancy;

pub use batch::{local_field, BatchEdtStage};
pub use integration::IntegrationStage;
pub use occupancy::{project_job, scatter_returns, Construction, OccupancyStage, OgmOptions};
