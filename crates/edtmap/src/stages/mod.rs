//! The pipeline's three stages (paper Fig. 1), each an object that owns
//! its buffers and runs its device work on a [`edtmap_core::Backend`]:
//! [`OccupancyStage`] (§IV-A), [`BatchEdtStage`] (§IV-B) and
//! [`IntegrationStage`] (§IV-C); with, from `edtmap-core`, what every
//! backend shares: [`exact`], the exact integration's host side, and the
//! occupancy construction's definitions ([`Construction`], [`OgmOptions`],
//! [`project_job`], [`scatter_returns`]).

mod batch;
mod integration;
mod occupancy;

pub use batch::{local_field, BatchEdtStage};
pub use edtmap_core::construction::{project_job, scatter_returns, Construction, OgmOptions};
pub use edtmap_core::exact;
pub use integration::IntegrationStage;
pub use occupancy::{fuse_on, OccupancyStage};
