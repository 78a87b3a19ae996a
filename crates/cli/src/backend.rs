//! `--backend cpu|gpu|auto`: which backend runs the pipeline's stages.

use anyhow::{Context, Result};
use clap::ValueEnum;
use edtmap::cpu::CpuBackend;
use edtmap::Backend;
use edtmap_gpu::GpuBackend;

/// Values of `--backend`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum BackendArg {
    /// All cores with rayon (the reference).
    #[default]
    Cpu,
    /// A GPU through wgpu (Vulkan, Metal or DX12; lavapipe in software).
    Gpu,
    /// A hardware GPU when there is one, else the CPU.
    Auto,
}

/// The backend the mapper runs on, chosen at run time.
pub(crate) type DynBackend = Box<dyn Backend>;

/// The mapper the commands drive.
pub(crate) type CliMapper = edtmap::Mapper<DynBackend>;

/// Opens the backend `arg` names. `gpu` without an adapter is an error
/// saying so; `auto` falls back to the CPU (software GPUs are slower than
/// the CPU backend, so `auto` never picks them).
pub(crate) fn open(arg: BackendArg, cpu: CpuBackend) -> Result<DynBackend> {
    open_for(arg, cpu, false)
}

/// [`open`] for a map that may be planar (`[global] planar = true`): its
/// integration runs on the CPU, so `auto` picks the CPU and `gpu` is
/// refused before any frame.
pub(crate) fn open_for(arg: BackendArg, cpu: CpuBackend, planar: bool) -> Result<DynBackend> {
    if planar {
        match arg {
            BackendArg::Gpu => anyhow::bail!(
                "--backend gpu: a planar map ([global] planar = true) is integrated on the CPU; use --backend cpu or auto"
            ),
            BackendArg::Auto => {
                eprintln!("--backend auto: a planar map is integrated on the CPU, using the CPU");
                return Ok(Box::new(cpu));
            }
            BackendArg::Cpu => {}
        }
    }
    match arg {
        BackendArg::Cpu => Ok(Box::new(cpu)),
        BackendArg::Gpu => Ok(Box::new(GpuBackend::new().context("--backend gpu")?)),
        BackendArg::Auto => match GpuBackend::new() {
            Ok(gpu) if !gpu.context().is_software() => Ok(Box::new(gpu)),
            Ok(gpu) => {
                eprintln!("--backend auto: {} is a software adapter, using the CPU", gpu.context().name());
                Ok(Box::new(cpu))
            }
            Err(e) => {
                eprintln!("--backend auto: using the CPU ({e})");
                Ok(Box::new(cpu))
            }
        },
    }
}
