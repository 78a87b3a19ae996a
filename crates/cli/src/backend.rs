//! `--backend cpu|gpu|auto`: which backend runs the pipeline's stages.

use anyhow::{Context, Result};
use clap::ValueEnum;
use edtmap::cpu::CpuBackend;
use edtmap::BackendChoice;

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
pub(crate) type DynBackend = edtmap::DynBackend;

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
    let (choice, name) = match arg {
        BackendArg::Cpu => (BackendChoice::Cpu, "cpu"),
        BackendArg::Gpu => (BackendChoice::Gpu, "gpu"),
        BackendArg::Auto => (BackendChoice::Auto, "auto"),
    };
    let opened = edtmap::open_backend(choice, cpu, planar).with_context(|| format!("--backend {name}"))?;
    if let Some(why) = opened.fell_back {
        eprintln!("--backend {name}: {why}, using the CPU");
    }
    Ok(opened.backend)
}
