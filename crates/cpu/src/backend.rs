//! [`CpuBackend`]: every device stage of the pipeline on the CPU's cores.

use crate::edt::{edt_into, ScanLayout};
use crate::integrate::separable::{update_exact, SeparableCache};
use crate::integrate::wavefront::{integrate_wavefront, WaveBuffers};
use crate::CpuError;
use edtmap_core::exact::{recompute_exact, ExactBuffers};
use edtmap_core::fixed_ray::{cast_fixed, FixedRay};
use edtmap_core::projection::mark_misses;
use edtmap_core::region::{Packing, Region};
use edtmap_core::{
    Backend, BackendError, BatchEdt, EdtField, Grid3, IntegrationJob, IntegrationReport, IntegrationWork, MapStamp,
    Observations, ProjectJob, WaveCounts,
};

/// Every stage on all cores with rayon; the reference backend.
///
/// It keeps, between frames, where each block of the global EDT has its
/// nearest obstacles (the wavefront's raise step reads it), keyed on the
/// map's [`MapStamp`]: a map changed by anything else is seen and the
/// cache dropped.
#[derive(Debug, Default)]
pub struct CpuBackend {
    edt: CpuEdt,
    waves: WaveBuffers,
    exact: ExactBuffers,
    separable: SeparableCache,
    seen: Option<MapStamp>,
    /// The window's batch EDT of an [`IntegrationWork::WavefrontMask`].
    window_edt: EdtField,
}

/// The batch EDT alone, with its scan layout.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct CpuEdt {
    layout: ScanLayout,
}

impl CpuBackend {
    /// A CPU backend whose batch EDT scans in `layout`.
    pub fn with_layout(layout: ScanLayout) -> Self {
        CpuBackend { edt: CpuEdt { layout }, ..Default::default() }
    }

    /// The batch EDT's scan layout.
    pub fn layout(&self) -> ScanLayout {
        self.edt.layout
    }

    /// Bytes of what the exact mode keeps between frames (the separable
    /// EDT's first two passes): not part of the map's own bytes.
    pub fn kept_bytes(&self) -> usize {
        self.separable.bytes()
    }
}

/// A fresh backend with the same layout (caches are not cloned).
impl Clone for CpuBackend {
    fn clone(&self) -> Self {
        CpuBackend::with_layout(self.edt.layout)
    }
}

impl BatchEdt for CpuEdt {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        edt_into(mask, |&o| o, self.layout, out).map_err(BackendError::from)
    }
}

impl BatchEdt for CpuBackend {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.edt.batch_edt(mask, out)
    }
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        cast_fixed(obs, rays, q);
        Ok(())
    }

    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        mark_misses(obs, job);
        Ok(())
    }

    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        let IntegrationJob { map, obstacles, cutoff, work } = job;
        if self.seen != Some(map.stamp()) {
            self.waves.forget_all();
        }
        let (written, waves, region) = match work {
            IntegrationWork::Wavefront { window, batch, offsets } => {
                let packing = Packing::new(Region::around(window, cutoff.reach + 1), cutoff)?;
                let (w, c) = integrate_wavefront(map, window, batch, &packing, offsets, &mut self.waves);
                (w, c, packing.region)
            }
            IntegrationWork::WavefrontMask { window, mask, offsets } => {
                let packing = Packing::new(Region::around(window, cutoff.reach + 1), cutoff)?;
                self.edt.batch_edt(mask, &mut self.window_edt)?;
                let (w, c) = integrate_wavefront(map, window, &self.window_edt, &packing, offsets, &mut self.waves);
                (w, c, packing.region)
            }
            IntegrationWork::Changes { blocks } => {
                let report = update_exact(map, &obstacles, blocks, cutoff, &mut self.separable);
                self.waves.forget(&report.changed_blocks);
                self.seen = Some(map.stamp());
                return Ok(report);
            }
            IntegrationWork::Recompute { region } => {
                let packing = Packing::new(region, cutoff)?;
                let w = recompute_exact(&mut self.edt, map, &obstacles, &packing, &mut self.exact)?;
                self.waves.forget(&w.changed_blocks);
                (w, WaveCounts::default(), region)
            }
        };
        self.seen = Some(map.stamp());
        Ok(written.into_report(region.len(), waves))
    }
}

impl From<CpuError> for BackendError {
    fn from(e: CpuError) -> Self {
        match e {
            CpuError::Core(c) => BackendError::Core(c),
            CpuError::Backend(b) => b,
            other => BackendError::Device(other.to_string()),
        }
    }
}
